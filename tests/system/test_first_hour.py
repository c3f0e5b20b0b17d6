"""A newcomer's first hour (issue 52): run_local.sh from another directory takes its paths from there,
RECONSWARM_PROFILE gets a profile from every process (the monitor too), a finished run leaves its record as one
file, a refused launch leaves nothing behind, and a run that ends without converging names its scenario's
warnings as the likely reason."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from reconswarm.scenario.generate import generate
from reconswarm.scenario.model import to_toml
from tests.support import PAPER, ROOT, free_port, summary

RUN_LOCAL = ROOT / "deploy" / "run_local.sh"


def _small(path: Path, duration_s: float = 4.0) -> Path:
    s = generate(2, 1, 3)
    text = to_toml(s).replace(f"duration_s = {s.meta.duration_s!r}", f"duration_s = {duration_s!r}", 1)
    assert f"duration_s = {duration_s!r}" in text
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def _env(**extra: str) -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=str(ROOT), **extra)


def test_relative_paths_and_profiles_from_another_directory(tmp_path: Path) -> None:
    caller = tmp_path / "elsewhere"
    _small(caller / "cred" / "small.toml")
    r = subprocess.run([str(RUN_LOCAL), "-s", "cred/small.toml", "-o", "out-rel", "--no-progress", "--router",
                        f"tcp/127.0.0.1:{free_port()}"], cwd=caller, capture_output=True, text=True, timeout=300,
                       env=_env(RECONSWARM_PROFILE="prof"))
    assert r.returncode in (0, 1), r.stderr
    out = caller / "out-rel"
    assert summary(out / "run.db")["finished"], r.stderr
    assert not (ROOT / "out-rel").exists()
    # every process wrote its profile, the monitor too, in the caller's prof/ (made by the launch)
    made = sorted(p.name.split("-")[0] for p in (caller / "prof").glob("*.prof"))
    assert made == ["agent.cli", "agent.cli", "monitor.cli", "reconswarm_bringup.cli_nodes", "simworld.cli"], made
    # the record is one file once the run is over: no WAL, no shared memory, no claim left
    left = {p.name for p in out.iterdir()}
    assert not left & {"run.db-wal", "run.db-shm", ".record.lock"}, left


def test_a_refused_launch_leaves_nothing_behind(tmp_path: Path) -> None:
    typo = tmp_path / "typo-b"
    r = subprocess.run([sys.executable, "-m", "reconswarm_bringup.cli_launch", "-s", str(tmp_path / "nope.toml"),
                        "-o", str(typo), "--no-progress"], cwd=ROOT, capture_output=True, text=True, timeout=60,
                       env=_env())
    assert r.returncode == 2 and "nope.toml: file not found" in r.stderr, r.stderr
    assert not typo.exists()
    # refused later, when planning the network (after the scenario was read): still nothing
    two = tmp_path / "twoB"
    r = subprocess.run([sys.executable, "-m", "reconswarm_bringup.cli_launch", "-s", str(PAPER), "-o", str(two),
                        "--no-progress", "--secure", "--router", f"tcp/[::1]:{free_port()}"], cwd=ROOT,
                       capture_output=True, text=True, timeout=60, env=_env())
    assert r.returncode == 2 and "IPv6" in r.stderr, r.stderr
    assert not two.exists()


def test_a_refused_launch_keeps_the_earlier_record_there(tmp_path: Path) -> None:
    out = tmp_path / "kept"
    r = subprocess.run([sys.executable, "-m", "reconswarm_bringup.cli", "sim", str(_small(tmp_path / "s.toml")),
                        "-o", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=300, env=_env())
    assert r.returncode in (0, 1), r.stderr
    (out / "run_id").write_text("small-123456\n")
    before = (out / "run.db").read_bytes()
    r = subprocess.run([sys.executable, "-m", "reconswarm_bringup.cli_launch", "-s", str(PAPER), "-o", str(out),
                        "--no-progress", "--secure", "--router", f"tcp/[::1]:{free_port()}"], cwd=ROOT,
                       capture_output=True, text=True, timeout=60, env=_env())
    assert r.returncode == 2 and "IPv6" in r.stderr, r.stderr
    assert sorted(p.name for p in out.iterdir()) == ["run.db", "run_id"]
    assert (out / "run.db").read_bytes() == before
    # refused by the claim (not a run record there): nothing added either
    (out / "run.db").write_bytes(b"not a record")
    r = subprocess.run([sys.executable, "-m", "reconswarm_bringup.cli_launch", "-s", str(PAPER), "-o", str(out),
                        "--no-progress"], cwd=ROOT, capture_output=True, text=True, timeout=60, env=_env())
    assert r.returncode == 2 and "not a run record" in r.stderr, r.stderr
    assert sorted(p.name for p in out.iterdir()) == ["run.db", "run_id"]


def _close_slots(tmp: Path) -> Path:
    # Offsets of agents 1 and 2 15.9 m apart, below d_max,12 = 17.18 m; 5 s: the mission cannot converge.
    text = PAPER.read_text()
    text = text.replace("offset_m = [-12.0, 20.78]", "offset_m = [-12.0, 52.0]", 1)
    text = text.replace("duration_s = 300.0", "duration_s = 5.0", 1)
    assert "52.0" in text and "duration_s = 5.0" in text
    path = tmp / "close-slots.toml"
    path.write_text(text)
    return path


def test_sim_names_the_warnings_when_it_ends_unconverged(tmp_path: Path) -> None:
    f = _close_slots(tmp_path)
    r = subprocess.run([sys.executable, "-m", "reconswarm_bringup.cli", "sim", str(f), "-o", str(tmp_path / "o")],
                       cwd=ROOT, capture_output=True, text=True, timeout=300, env=_env())
    assert r.returncode == 1, r.stderr
    lines = r.stderr.splitlines()
    warn = "offsets of agents 1 and 2 are 15.90 m apart, below d_max,ij = 17.18 m (Assumption 4.1)"
    assert warn in lines[0], lines  # at the start
    at = next(i for i, ln in enumerate(lines) if ln.startswith("not converged in 5.0 s; the likely reason"))
    assert warn in lines[at + 1], lines  # and again at the end, as the likely reason
    assert sorted(p.name for p in (tmp_path / "o").iterdir()) == ["run.db"]


def test_launch_names_the_warnings_when_it_ends_unconverged(tmp_path: Path) -> None:
    f = _close_slots(tmp_path)
    r = subprocess.run([sys.executable, "-m", "reconswarm_bringup.cli", "launch", "-s", str(f), "-o",
                        str(tmp_path / "o"), "--no-progress", "--router", f"tcp/127.0.0.1:{free_port()}"],
                       cwd=ROOT, capture_output=True, text=True, timeout=300, env=_env())
    assert r.returncode == 1, r.stderr
    lines = r.stderr.splitlines()
    warn = "offsets of agents 1 and 2 are 15.90 m apart"
    assert lines[0].startswith("reconswarm launch: warning: ") and warn in lines[0], lines
    assert not any(ln.startswith("run_local:") for ln in lines), lines
    at = next(i for i, ln in enumerate(lines) if "not converged in 5.0 s; the likely reason" in ln)
    assert warn in lines[at + 1], lines


def test_ctrl_c_during_start_up_is_quiet(tmp_path: Path) -> None:
    import signal
    import time

    from tests.support import assert_all_gone, launcher_cmd, tick_count

    out = tmp_path / "o"
    # A terminal's Ctrl-C: SIGINT to the whole foreground process group (the launcher leads its own here).
    proc = subprocess.Popen(launcher_cmd(out, "-n", "3"), cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=_env(), start_new_session=True)
    deadline = time.monotonic() + 120
    tsv = out / "processes.tsv"
    while not (tsv.exists() and "simworld" in tsv.read_text()):  # every process started, most still importing
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert_all_gone(out)
    for log in (out / "logs").glob("*.log"):
        text = log.read_text()
        assert "Traceback" not in text and "KeyboardInterrupt" not in text, f"{log.name}:\n{text}"
    assert "Traceback" not in err, err
    if tick_count(out / "run.db") == 0:  # no record, or one without a tick: the launcher says which
        assert ("stopped during start-up: no record yet" in err
                or "stopped during start-up: no tick recorded yet" in err), err
        assert "cannot be read" not in err, err
