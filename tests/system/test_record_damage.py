"""`reconswarm monitor summary|events|export|plot` on damaged run records: one line naming the file and
what is wrong, exit 2, never a traceback. The records are real (a `sim` run), damaged the way a disk or a
user does it: random bytes over the middle of the file, a table dropped, a blob or a JSON value changed."""

from __future__ import annotations

import os
import shutil
import sqlite3
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

pytestmark = pytest.mark.parallel  # (no launch, no router, no wall-clock bound: beside the unit tests)

ROOT = Path(__file__).resolve().parents[2]
PAPER_TEXT = (ROOT / "deploy" / "scenarios" / "paper.toml").read_text()
COMMANDS = ["summary", "events", "export", "plot"]


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "reconswarm_bringup.cli", *args], capture_output=True, text=True,
                          timeout=120, cwd=ROOT)


def monitor(command: str, db: Path, tmp: Path) -> subprocess.CompletedProcess[str]:
    extra = ["-o", str(tmp / "plot.png")] if command == "plot" else []
    return cli("monitor", command, str(db), *extra)


@pytest.fixture(scope="module")
def record(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("rec")
    f = d / "short.toml"
    f.write_text(PAPER_TEXT.replace("duration_s = 300.0", "duration_s = 60.0"))
    r = cli("sim", str(f), "-o", str(d / "run"), "--json")
    assert r.returncode == 1, r.stderr  # not converged in 60 s, but a complete record
    db = d / "run" / "run.db"
    con = sqlite3.connect(db)  # fold the WAL into the file: the copies below are self-contained
    con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    con.close()
    return db


def damaged(record: Path, tmp: Path, how: Callable[[Path], None]) -> Path:
    db = tmp / "run.db"
    shutil.copy(record, db)
    how(db)
    return db


def sql(statement: str) -> Callable[[Path], None]:
    def run(db: Path) -> None:
        con = sqlite3.connect(db)
        con.execute(statement)
        con.commit()
        con.close()
    return run


def random_middle(db: Path) -> None:
    size = db.stat().st_size
    assert size > 64 * 1024
    with db.open("r+b") as f:
        f.seek(size // 2)
        f.write(os.urandom(8192))


def assert_one_line_error(r: subprocess.CompletedProcess[str], db: Path, what: str) -> None:
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr
    lines = r.stderr.splitlines()
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith(f"reconswarm: error: {db}: ") and what in lines[0], lines[0]


def test_the_intact_record_reads(record, tmp_path):
    for command in COMMANDS:
        r = monitor(command, record, tmp_path)
        assert r.returncode == 0 and r.stderr.strip() == "", (command, r.stderr)


# The issue's three cases, every command, each in its own process.
ISSUE = [
    ("random-8kB-middle", random_middle, "database disk image is malformed"),
    ("missing-table-ticks", sql("DROP TABLE ticks"), "no such table: ticks"),
    ("bad-blob", sql("UPDATE ticks SET px = x'0102' WHERE k = 100"), "ticks k=100: px holds 2 bytes, expected 80"),
]
# Which commands read the damaged part (events reads only meta and events).
READS = {"random-8kB-middle": {"summary", "export", "plot"}, "missing-table-ticks": {"summary", "export", "plot"},
         "bad-blob": {"summary", "export", "plot"}}


@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.parametrize(("name", "how", "what"), ISSUE, ids=[c[0] for c in ISSUE])
def test_issue_cases(record, tmp_path, name, how, what, command):
    db = damaged(record, tmp_path, how)
    r = monitor(command, db, tmp_path)
    if command in READS[name]:
        assert_one_line_error(r, db, what)
        assert r.stdout == ""  # export reads every tick before it writes a row
    else:  # a command that does not read the damaged part still works
        assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr


# More damage, every command through typer's runner in this process (one import for the whole table).
MORE = [
    ("missing-events", sql("DROP TABLE events"), "no such table: events", {"summary", "events", "plot"}),
    ("missing-contacts", sql("DROP TABLE contacts"), "no such table: contacts", {"summary"}),
    ("missing-counters", sql("DROP TABLE counters"), "no such table: counters", {"summary"}),
    ("missing-gaps", sql("DROP TABLE gaps"), "no such table: gaps", {"summary"}),
    ("missing-meta", sql("DROP TABLE meta"), "not a reconswarm run record (no such table: meta)", set(COMMANDS)),
    ("blob-as-text", sql("UPDATE ticks SET py = 'hello' WHERE k = 7"), "ticks k=7: py holds str", {"summary", "export",
                                                                                                  "plot"}),
    ("alive-blob-short", sql("UPDATE ticks SET alive = x'01' WHERE k = 3"), "ticks k=3: alive holds 1 bytes",
     {"summary", "export", "plot"}),
    ("tick-time-text", sql("UPDATE ticks SET t = 'soon' WHERE k = 5"), "ticks k=5: a column of the wrong type",
     {"summary", "export", "plot"}),
    ("event-json", sql("UPDATE events SET data = '{bad' WHERE seq = 1"), "events seq=1: not valid JSON",
     {"summary", "events", "plot"}),
    ("event-shape", sql("UPDATE events SET data = '{\"t\": \"x\"}' WHERE seq = 1"), "events seq=1: not an event",
     {"summary", "events", "plot"}),
    ("agent-ids-json", sql("UPDATE meta SET value = '[1,2' WHERE key = 'agent_ids'"),
     "meta.agent_ids: not valid JSON", set(COMMANDS)),
    ("agent-ids-other", sql("UPDATE meta SET value = '[1,2,3]' WHERE key = 'agent_ids'"),
     "meta.agent_ids: not the ids of the record's scenario", set(COMMANDS)),
    ("scenario-toml", sql("UPDATE meta SET value = 'garbage' WHERE key = 'scenario_toml'"), "not valid TOML",
     set(COMMANDS)),
    ("wall-time", sql("UPDATE meta SET value = 'fast' WHERE key = 'wall_time_s'"), "meta.wall_time_s: not a number",
     set(COMMANDS)),
    ("contact-gap-text", sql("INSERT INTO contacts(kind, a, b, t_start, gap_m) VALUES ('collision', '1', '2', 1.0, "
                             "'deep')"), "contacts seq=1: a column of the wrong type", {"summary"}),
    ("truncated-file", lambda db: os.truncate(db, db.stat().st_size // 3),
     "damaged run record: database disk image is malformed", set(COMMANDS)),
]


@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.parametrize(("name", "how", "what", "reads"), MORE, ids=[c[0] for c in MORE])
def test_more_damage_in_process(record, tmp_path, name, how, what, reads, command):
    from typer.testing import CliRunner

    from reconswarm_bringup.cli import app

    db = damaged(record, tmp_path, how)
    extra = ["-o", str(tmp_path / "plot.png")] if command == "plot" else []
    r = CliRunner().invoke(app, ["monitor", command, str(db), *extra])
    if command in reads:
        assert r.exit_code == 2, (r.output, r.exception)
        lines = r.stderr.splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"reconswarm: error: {db}: ") and what in lines[0], r.stderr
    else:
        assert r.exit_code == 0, (r.output, r.exception)


def test_random_damage_anywhere_never_tracebacks(record, tmp_path):
    """8 kB of random bytes at 12 places through the file: every command exits 0 or 2 with one line."""
    size = record.stat().st_size
    for i, at in enumerate(range(0, size, size // 12)):
        db = tmp_path / f"r{i}.db"
        shutil.copy(record, db)
        with db.open("r+b") as f:
            f.seek(at)
            f.write(os.urandom(8192))
        for command in ("summary", "export"):
            r = monitor(command, db, tmp_path)
            assert "Traceback" not in r.stderr and r.returncode in (0, 2), (at, command, r.stderr)
            if r.returncode == 2:
                assert len(r.stderr.splitlines()) == 1 and str(db) in r.stderr, r.stderr


@pytest.mark.parametrize("command", ["plot", "export"])
def test_unwritable_output_file(record, tmp_path, command):
    (tmp_path / "afile").write_text("")
    for out in ("/proc/x/run.out", str(tmp_path / "afile" / "run.out")):
        r = cli("monitor", command, str(record), "-o", out)
        assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
        lines = r.stderr.splitlines()
        assert len(lines) == 1 and f"-o {out}: cannot write there" in lines[0], r.stderr
