"""run_local.sh's arguments (reconswarm_bringup/validate.py, called by the launcher): what the issue found
accepted or crashing is refused with one line and exit 2 before any process starts; unwritable output
directories (run_local.sh and sim) likewise."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from reconswarm.errors import BadInput
from reconswarm.scenario.generate import generate
from reconswarm.scenario.model import to_toml
from reconswarm_bringup import validate

pytestmark = pytest.mark.parallel  # (no launch, no router, no wall-clock bound: beside the unit tests)

ROOT = Path(__file__).resolve().parents[2]
RUN_LOCAL = ROOT / "deploy" / "run_local.sh"
MEMINFO = "MemTotal:       24684096 kB\nMemFree:         1000000 kB\nMemAvailable:   23929832 kB\n"


def processes_mentioning(text: str) -> list[int]:
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit() and int(d.name) != os.getpid():
            try:
                if text.encode() in (d / "cmdline").read_bytes():
                    out.append(int(d.name))
            except OSError:
                continue
    return out


def refused(cmd: list[str], out: Path, *expect: str) -> str:
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert r.returncode == 2, (cmd, r.stdout, r.stderr)
    assert "Traceback" not in r.stderr
    lines = r.stderr.splitlines()
    assert len(lines) == 1, r.stderr
    for e in expect:
        assert e in lines[0], lines[0]
    # Nothing was started: no process list, no logs, no process carrying the output directory.
    assert not (out / "processes.tsv").exists() and not (out / "logs").exists()
    assert processes_mentioning(str(out)) == []
    return lines[0]


def run_local(out: Path, *args: str) -> list[str]:
    return [str(RUN_LOCAL), "-o", str(out), "--no-progress", *args]


def launcher(out: Path, *args: str) -> list[str]:
    return [sys.executable, "-m", "reconswarm_bringup.cli_launch", "-o", str(out), "--no-progress", *args]


# ------------------------------------------------------------------------ the issue's cases, run_local.sh

ISSUE = [
    (["-n", "100000"], ["-n 100000: 100000 agent processes need about", "GB available"]),
    (["-n", "12345678901234567890"], ["-n 12345678901234567890: ", "agent processes need about"]),
    (["--timeout", "-1"], ["--timeout: must be a positive number of seconds, got -1.0"]),
    (["--timeout", "nan"], ["--timeout: must be a positive number of seconds, got nan"]),
    (["--router", "tcp/127.0.0.1:99999"], ["--router: port must be 1..65535, got '99999'"]),
]


@pytest.mark.parametrize(("args", "expect"), ISSUE, ids=[" ".join(a) for a, _ in ISSUE])
def test_run_local_refuses(tmp_path, args, expect):
    out = tmp_path / "run"
    refused(run_local(out, *args), out, *expect)


@pytest.mark.parametrize("args", [["--timeout", "inf"], ["--timeout", "0"], ["--speed", "inf"], ["--speed", "nan"],
                                  ["-n", "0"], ["-n", "abc"], ["--timeout", "soon"], ["--router", "tcp/127.0.0.1:0"],
                                  ["--router", "tcp/127.0.0.1"], ["--router", "127.0.0.1:7447"],
                                  ["--router", "udp/127.0.0.1:7447"], ["--router", "tcp/bad host:7447"],
                                  ["--clock", "fast"], ["-n", "3", "-s", "deploy/scenarios/paper.toml"]])
def test_launcher_refuses(tmp_path, args):
    out = tmp_path / "run"
    refused(launcher(out, *args), out, "run_local: error: ")


def test_the_memory_figure_is_what_the_run_needs(tmp_path):
    """A scenario file whose agent processes exceed the available memory is refused too, naming the file."""
    avail = validate.available_memory_mb()
    assert avail is not None
    n = math.ceil(avail / validate.PEAK_RSS_MB["agent"] * 1.3)
    f = tmp_path / "big.toml"
    f.write_text(to_toml(generate(n, 3, 0)))
    out = tmp_path / "run"
    line = refused(launcher(out, "-s", str(f)), out, f"-s {f}: {n} agent processes need about")
    need_gb = float(line.split("need about ")[1].split(" GB")[0].replace(",", ""))
    assert need_gb == pytest.approx(validate.run_memory_mb(n) / 1024, abs=0.06)


def test_refused_run_leaves_the_previous_record_alone(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "run.db").write_bytes(b"previous run")
    refused(launcher(out, "--fault", "kill:agent:99@10"), out, "the scenario has no agent 99")
    assert (out / "run.db").read_bytes() == b"previous run"


# ------------------------------------------------------------------------------- unwritable output dir


@pytest.mark.parametrize("where", ["proc", "under-a-file"])
def test_unwritable_output_dir(tmp_path, where):
    (tmp_path / "afile").write_text("")
    out = Path("/proc/x") if where == "proc" else tmp_path / "afile" / "run"
    refused(run_local(out), out, f"-o {out}: cannot write there (")
    paper = ROOT / "deploy" / "scenarios" / "paper.toml"
    r = subprocess.run([sys.executable, "-m", "reconswarm_bringup.cli", "sim", str(paper), "-o", str(out), "--json"],
                       capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert r.returncode == 2 and r.stdout == "" and "Traceback" not in r.stderr
    assert r.stderr.splitlines() == [f"reconswarm: error: -o {out}: cannot write there (" +
                                     ("No such file or directory)" if where == "proc" else "Not a directory)")]


@contextmanager
def read_only_dir(base: Path) -> Iterator[tuple[Path, str]]:
    """A directory nobody can write in, and why writing fails: mode 555 for a user; for root (CI runs as
    root, and root writes through permissions) the directory bind-mounted read-only onto itself, which
    refuses every writer. A root that cannot mount fails here, with the reason, rather than skip."""
    ro = base / "ro"
    ro.mkdir(mode=0o555)
    if os.geteuid() != 0:
        yield ro, "Permission denied"
        return
    for args in (["--bind", str(ro), str(ro)], ["-o", "remount,bind,ro", str(ro)]):
        r = subprocess.run(["mount", *args], capture_output=True, text=True, timeout=30)
        if r.returncode != 0:
            subprocess.run(["umount", str(ro)], capture_output=True, timeout=30)
            pytest.fail(f"as root, a read-only bind mount is needed and `mount {' '.join(args)}` failed: "
                        f"{r.stderr.strip()}")
    try:
        yield ro, "Read-only file system"
    finally:
        subprocess.run(["umount", str(ro)], check=True, capture_output=True, timeout=30)


def test_read_only_output_dir(tmp_path):
    with read_only_dir(tmp_path) as (ro, why):
        with pytest.raises(OSError):  # nobody, root included, can write there
            (ro / "probe").write_text("")
        refused(run_local(ro), ro, f"-o {ro}: cannot write there ({why})")
        paper = ROOT / "deploy" / "scenarios" / "paper.toml"
        r = subprocess.run([sys.executable, "-m", "reconswarm_bringup.cli", "sim", str(paper), "-o", str(ro),
                            "--json"], capture_output=True, text=True, timeout=120, cwd=ROOT)
        assert r.returncode == 2 and r.stdout == "" and "Traceback" not in r.stderr
        assert r.stderr.splitlines() == [f"reconswarm: error: -o {ro}: cannot write there ({why})"]
        assert list(ro.iterdir()) == []


# ------------------------------------------------------------------------------------- pure functions


def test_endpoint():
    assert validate.endpoint("--router", "tcp/127.0.0.1:7447") == ("tcp", "127.0.0.1", 7447)
    assert validate.endpoint("--router", "tls/[::1]:7600") == ("tls", "::1", 7600)
    assert validate.endpoint("--router", "tcp/localhost:1#iface=lo") == ("tcp", "localhost", 1)
    for bad in ("tcp/127.0.0.1:99999", "tcp/127.0.0.1:0", "tcp/127.0.0.1:-1", "tcp/127.0.0.1:", "tcp/:7447",
                "tcp/127.0.0.1", "serial/ttyS0", "127.0.0.1:7447", "tcp/a b:1", "tcp/[nothost]:1",
                "tcp/127.0.0.1:٣٣"):
        with pytest.raises(BadInput, match=r"^--router: "):
            validate.endpoint("--router", bad)


def test_memory_check_from_meminfo():
    avail = validate.available_memory_mb(MEMINFO)
    assert avail is not None and avail == pytest.approx(23929832 / 1024)
    fits = math.floor((avail - validate.run_memory_mb(0)) / validate.PEAK_RSS_MB["agent"])
    validate.machine_holds("-n", fits, avail)  # the largest run that fits ...
    with pytest.raises(BadInput, match=rf"^-n: {fits + 1} agent processes need about 22\.\d GB .* 22\.8 GB available$"):
        validate.machine_holds("-n", fits + 1, avail)  # ... and one more agent does not
    assert validate.available_memory_mb("MemTotal: 1 kB\n") is None
    validate.machine_holds("-n", 10**9, None)  # unknown: not refused on a guess


def test_seconds_and_speed():
    for ok in (None, 0.001, 600.0):
        validate.positive_seconds("--timeout", ok)
    for bad in (0.0, -1.0, float("nan"), float("inf"), float("-inf")):
        with pytest.raises(BadInput, match=r"^--timeout: must be a positive number of seconds"):
            validate.positive_seconds("--timeout", bad)
        with pytest.raises(BadInput, match=r"^--speed: "):
            validate.positive_finite("--speed", bad)
