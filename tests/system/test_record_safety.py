"""Nothing a command reads is ever destroyed by it (issue 22, case 4).

- `monitor export|plot|animate -o` naming the record being read (the same path, another spelling of it, a
  link to it) is refused: one line, exit 2, the record intact.
- `reconswarm sim -o DIR` while a launched run writes DIR/run.db is refused (exit 2, one line) and the
  live record goes on to be the launch's own; afterwards sim still does not replace that launched record.
- `reconswarm sim -o DIR` while another engine holds DIR is refused; sim replaces its own finished record.
- a second launch into the directory of a live launch is refused (exit 2) before it deletes anything.
"""

from __future__ import annotations

import json
import signal
import subprocess
from pathlib import Path

import pytest

from reconswarm.scenario.generate import generate
from reconswarm.scenario.model import to_toml
from reconswarm_bringup.outdir import RecordClaim
from tests.support import ROOT, launcher_cmd, reconswarm, summary, tick_count, wait_for_ticks


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A three-agent scenario and a finished in-process record of it."""
    d = tmp_path_factory.mktemp("tiny")
    path = d / "tiny.toml"
    path.write_text(to_toml(generate(3, 1, 1)))
    r = reconswarm("sim", str(path), "-o", str(d / "sim"), "--json")
    assert r.returncode == 0, r.stderr
    return path, d / "sim" / "run.db"


def _refused(r: subprocess.CompletedProcess[str], needle: str) -> None:
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1 and needle in lines[0], lines


@pytest.mark.parallel  # (no launch: beside the unit tests)
@pytest.mark.parametrize("cmd", [("export", "--format", "csv"), ("export", "--format", "mcap"), ("plot",),
                                 ("animate",)])
def test_a_reader_never_writes_over_its_record(tiny: tuple[Path, Path], tmp_path: Path, cmd: tuple[str, ...]) -> None:
    _, db = tiny
    before = db.read_bytes()
    link = tmp_path / "link.db"
    link.symlink_to(db)
    for target in (db, db.parent / ".." / db.parent.name / db.name, link):
        r = reconswarm("monitor", cmd[0], str(db), *cmd[1:], "-o", str(target))
        _refused(r, "is the record this command reads")
    assert db.read_bytes() == before
    assert summary(db)["mode"] == "inprocess"


@pytest.mark.parallel  # (no launch: beside the unit tests)
def test_sim_replaces_its_own_record_but_not_a_claimed_dir(tiny: tuple[Path, Path], tmp_path: Path) -> None:
    path, _ = tiny
    out = tmp_path / "sim"
    for _ in range(2):  # a second sim into the same directory replaces the first one's record
        r = reconswarm("sim", str(path), "-o", str(out), "--json")
        assert r.returncode == 0, r.stderr
    before = (out / "run.db").read_bytes()
    with RecordClaim(out):  # as a sim still writing there holds it
        r = reconswarm("sim", str(path), "-o", str(out))
    _refused(r, "another run is writing its record there")
    assert (out / "run.db").read_bytes() == before
    (out / "run.db").write_bytes(b"not a database at all")
    _refused(reconswarm("sim", str(path), "-o", str(out)), "not a run record")


def test_sim_refuses_a_live_launch_dir_and_its_record(tiny: tuple[Path, Path], out: Path) -> None:
    path, _ = tiny
    out.mkdir(parents=True)
    # realtime at 4x: the run lasts long enough to be written to while sim is tried
    launch = subprocess.Popen(launcher_cmd(out, "-s", str(path), "--clock", "realtime", "--speed", "4", "--json"),
                              cwd=ROOT, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        wait_for_ticks(out / "run.db", 5, launch, 120, "the launch did not start recording")
        r = reconswarm("sim", str(path), "-o", str(out))
        _refused(r, "run is writing its record there")  # (the launch's claim on the directory)
        # a second launch into the same directory (on its own router) neither starts nor deletes the record
        second = subprocess.run(launcher_cmd(out, "-s", str(path), "--json"), cwd=ROOT, text=True,
                                capture_output=True, timeout=120)
        assert second.returncode == 2 and "another run is writing its record there" in second.stderr, second.stderr
        assert tick_count(out / "run.db") >= 5
        launch.send_signal(signal.SIGINT)  # (the run stopped as a user would: the record is the launch's all the same)
        stdout, stderr = launch.communicate(timeout=120)
    finally:
        if launch.poll() is None:
            launch.kill()
            launch.communicate()
    assert launch.returncode == 130, stderr[-3000:]
    s = json.loads(stdout)
    assert s["mode"] == "realtime" and s["end_reason"] == "stopped", s
    assert summary(out / "run.db")["mode"] == "realtime"
    # the run is over: its record is still not sim's to replace
    _refused(reconswarm("sim", str(path), "-o", str(out)), "the record of a launched run (mode realtime)")
    assert summary(out / "run.db")["mode"] == "realtime"
