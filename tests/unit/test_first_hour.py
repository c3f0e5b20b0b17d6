"""Issue 52 (a newcomer's first hour), the pure parts: each launch without -o gets its own directory and
runs/latest links to the newest; an output directory is checked without being made; the end of an unconverged
run names the scenario's warnings."""

from __future__ import annotations

from pathlib import Path

import pytest

from reconswarm.cli.console import unconverged_reason
from reconswarm.cli.outputs import creatable_dir
from reconswarm.errors import BadInput
from reconswarm_bringup.outdir import link_latest, new_run_dir


def test_each_run_gets_its_own_directory_and_latest_follows(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    first = new_run_dir(runs, now=0.0)
    first.mkdir(parents=True)
    (first / "run.db").write_text("first")
    second = new_run_dir(runs, now=0.0)  # the same second: a suffix, never the same directory
    assert second != first and second.name == f"{first.name}-2"
    second.mkdir()
    link_latest(first)
    assert (runs / "latest").resolve() == first.resolve()
    link_latest(second)
    assert (runs / "latest").resolve() == second.resolve()
    assert (first / "run.db").read_text() == "first"


def test_a_real_latest_directory_is_kept_aside(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    (runs / "latest").mkdir(parents=True)
    (runs / "latest" / "run.db").write_text("old")
    new = new_run_dir(runs)
    new.mkdir()
    link_latest(new)
    kept = [p for p in runs.iterdir() if p.name.startswith("latest-")]
    assert len(kept) == 1 and (kept[0] / "run.db").read_text() == "old"
    assert (runs / "latest").is_symlink() and (runs / "latest").resolve() == new.resolve()


def test_creatable_dir_makes_nothing(tmp_path: Path) -> None:
    creatable_dir("-o", tmp_path / "a" / "b")
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "f").write_text("")
    with pytest.raises(BadInput, match=r"-o .*f/x: cannot write there \(a file stands"):
        creatable_dir("-o", tmp_path / "f" / "x")


def test_unconverged_reason() -> None:
    warns = ["s.toml: agents: offsets of agents 2 and 5 are 9.60 m apart, below d_max,ij = 18.04 m"]
    ended = {"converged": False, "finished": True, "duration_s": 20.0}
    assert unconverged_reason(ended, warns) == [
        "not converged in 20.0 s; the likely reason is the scenario's warning (reconswarm scenario check):",
        f"  {warns[0]}"]
    assert unconverged_reason({**ended, "converged": True}, warns) == []
    assert unconverged_reason({**ended, "finished": False}, warns) == []  # stopped early: that is the reason
    assert unconverged_reason(ended, []) == []


def test_an_unknown_scenario_key_suggests_the_near_one(tmp_path: Path) -> None:
    from reconswarm.scenario.model import load
    from tests.support import PAPER

    f = tmp_path / "k.toml"
    f.write_text(PAPER.read_text().replace("k_att =", "k_attr =", 1))
    with pytest.raises(BadInput, match=r"k\.toml: planner\.k_attr: unknown key \(did you mean k_att\?\)$"):
        load(f)
    f.write_text(PAPER.read_text().replace("k_att =", "zzz = 1\nk_att =", 1))
    with pytest.raises(BadInput, match=r"planner\.zzz: unknown key$"):
        load(f)


def test_scenario_check_counts_in_words(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from reconswarm.scenario.generate import generate
    from reconswarm.scenario.model import to_toml
    from reconswarm_bringup.cli import app

    f = tmp_path / "one.toml"
    f.write_text(to_toml(generate(1, 1, 0)))
    r = CliRunner().invoke(app, ["scenario", "check", str(f)])
    assert r.exit_code == 0 and "ok (1 agent, 1 obstacle, planner" in r.stdout, r.stdout


def test_launch_help_at_80_columns_says_the_default_out_whole() -> None:
    import os
    import subprocess
    import sys

    from tests.support import ROOT

    r = subprocess.run([sys.executable, "-m", "reconswarm_bringup.cli", "launch", "--help"], cwd=ROOT,
                       capture_output=True, text=True, timeout=60, env=dict(os.environ, COLUMNS="80"))
    assert r.returncode == 0, r.stderr
    text = " ".join(" ".join(r.stdout.replace("│", " ").split()).split())
    assert "(default: a new runs/YYYYMMDD-HHMMSS in the project; runs/latest links to the newest)" in text, r.stdout
    assert "…" not in r.stdout


def test_csv_export_in_bulk_writes_each_known_cell_as_repr(tmp_path: Path) -> None:
    import dataclasses
    import io

    import numpy as np

    from monitor.csv_export import CHUNK_TICKS, export_csv
    from reconswarm.record.store import RunRecord
    from reconswarm.scenario.generate import generate
    from reconswarm_bringup import engine

    s = generate(3, 1, 2)
    engine.run(engine.SimConfig(s, tmp_path, progress=False))
    with RunRecord(tmp_path / "run.db") as rec:
        tk = rec.ticks()
        assert tk.t.size > CHUNK_TICKS  # more than one chunk
        px = tk.px.copy()
        px[7, 1] = np.nan  # an agent unknown at a tick: no row there
        tk = dataclasses.replace(tk, px=px)
        got = io.StringIO()
        n = export_csv(rec, got, None, tk)
        want = ["t_s,agent,px_m,py_m,theta_rad"]
        for row in range(tk.t.size):
            for col, aid in enumerate(rec.ids):
                if np.isfinite(tk.px[row, col]):
                    want.append(f"{tk.t[row]:.6f},{int(aid)},{float(tk.px[row, col])!r},{float(tk.py[row, col])!r},"
                                 f"{float(tk.theta[row, col])!r}")
    assert got.getvalue().splitlines() == want and n == len(want) - 1


def _system_python_without_zenoh() -> str:
    import subprocess

    for exe in ("/usr/bin/python3", "/usr/local/bin/python3"):
        if Path(exe).exists() and subprocess.run([exe, "-c", "import zenoh"], capture_output=True).returncode != 0:
            return exe
    pytest.skip("no Python without zenoh on this machine")


def test_ros2_echo_from_another_python_runs_in_the_project_venv() -> None:
    import subprocess

    from tests.support import ROOT

    exe = _system_python_without_zenoh()
    r = subprocess.run([exe, str(ROOT / "deploy" / "ros2_echo.py"), "--help"], cwd="/", capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0 and r.stdout.startswith("usage: ros2_echo.py"), r.stderr


def test_ros2_echo_without_any_environment_says_how_in_one_line(tmp_path: Path) -> None:
    import shutil
    import subprocess

    from tests.support import ROOT

    exe = _system_python_without_zenoh()
    (tmp_path / "deploy").mkdir()
    copy = shutil.copy(ROOT / "deploy" / "ros2_echo.py", tmp_path / "deploy")  # (no .venv beside it)
    r = subprocess.run([exe, str(copy), "--help"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2, r.stderr
    (line,) = r.stderr.strip().splitlines()
    assert line.startswith("ros2_echo.py: error: needs the Python packages eclipse-zenoh and rosbags"), line


def test_the_security_example_finds_agent_3_in_an_agent_hosts_file(tmp_path: Path) -> None:
    from tests.support import ROOT

    doc = (ROOT / "docs" / "security.md").read_text()
    block = next(b.split("```", 1)[0] for b in doc.split("```python\n")[1:] if "observer.json5" in b)
    head = block.split("# the clock and the events")[0]  # up to the sessions: the file names, no network
    (tmp_path / "secrets").mkdir()
    (tmp_path / "run_id").write_text("paper-abc123\n")
    for name in ("observer", "monitor", "agents-1-5", "agents-6-9,11"):
        (tmp_path / "secrets" / f"{name}.json5").write_text("{}")
    scope: dict[str, object] = {}
    exec(compile(head.replace("runs/latest", str(tmp_path)), "docs/security.md", "exec"), scope)
    agent_role = scope["agent_role"]
    assert agent_role(3).name == "agents-1-5.json5"  # type: ignore[operator]
    assert agent_role(11).name == "agents-6-9,11.json5"  # type: ignore[operator]
    with pytest.raises(SystemExit, match="no credentials for agent 10"):
        agent_role(10)  # type: ignore[operator]
