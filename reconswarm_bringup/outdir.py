"""Output directories and files: a command never destroys what another run is writing, nor what it reads.

- `RecordClaim`: the in-process engine's hold on OUTDIR while it writes OUTDIR/run.db, an exclusive `flock`
  on OUTDIR/.record.lock (released by the kernel however the process ends; the file is removed as the run
  ends). Before it replaces run.db it
  refuses (BadInput, exit 2) when
  * another engine holds the claim (a `reconswarm sim` still writing there);
  * a launched run is alive there: a pid of OUTDIR/processes.tsv is alive and is a process of that run (its
    command line names OUTDIR/scenario.toml, as every process of a launch does);
  * OUTDIR/run.db is not a record the engine wrote (a launched run's record, or not a run record at all):
    the engine replaces only its own records.
(An output path that is the very file a command reads is refused by reconswarm/cli/outputs.py's `not_the_input`.)
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import sqlite3
from pathlib import Path
from typing import IO

from reconswarm.errors import BadInput

LOCK_FILE = ".record.lock"
ENGINE_MODE = "inprocess"  # the `mode` meta of a record the in-process engine wrote


def _live_launch_pid(out: Path) -> int | None:
    """A live process of a launched run in `out` (by OUTDIR/processes.tsv and its command line), else None."""
    tsv = out / "processes.tsv"
    try:
        lines = tsv.read_text().splitlines()
    except OSError:
        return None
    marker = str((out / "scenario.toml").resolve()).encode()
    for line in lines:
        parts = line.split("\t")
        if len(parts) != 3 or not (parts[2].isascii() and parts[2].isdigit()):
            continue
        try:
            cmdline = Path(f"/proc/{parts[2]}/cmdline").read_bytes()
        except OSError:
            continue  # gone
        if marker in cmdline.split(b"\0"):  # (the launcher passes OUTDIR resolved)
            return int(parts[2])
    return None


def record_mode(db: Path) -> str | None:
    """The `mode` meta of an existing record; None if db is not a readable run record."""
    try:
        con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    except sqlite3.Error:
        return None
    try:
        row = con.execute("SELECT value FROM meta WHERE key = 'mode'").fetchone()
    except sqlite3.Error:
        return None
    finally:
        con.close()
    return None if row is None else str(row[0])


class RecordClaim:
    """The engine's exclusive hold on OUTDIR while it writes OUTDIR/run.db (see the module's docstring)."""

    def __init__(self, out: Path, option: str = "-o", replaces: tuple[str, ...] | None = (ENGINE_MODE,),
                 what: str = "the in-process engine (reconswarm sim, sweep)") -> None:
        """replaces: the record modes this writer may replace (None: any run record; the launcher's choice,
        which still may not take a directory a live run holds)."""
        self.out = out
        self.option = option
        self.replaces = replaces
        self.what = what
        self._fh: IO[str] | None = None

    def acquire(self) -> None:
        out, opt = self.out, self.option
        out.mkdir(parents=True, exist_ok=True)
        path = out / LOCK_FILE
        while True:
            fh = path.open("a+")
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                break
            try:  # the holder before us removes the file as it releases it: then lock the file that is there now
                if os.stat(path).st_ino == os.fstat(fh.fileno()).st_ino:
                    break
            except FileNotFoundError:
                pass
            fh.close()
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.seek(0)
            holder = fh.read().strip()
            fh.close()
            pid = "?"
            with contextlib.suppress(ValueError, AttributeError):
                pid = json.loads(holder).get("pid", "?")
            raise BadInput(f"{opt} {out}: another run is writing its record there (pid {pid}); "
                           f"choose another directory") from None
        try:
            live = _live_launch_pid(out)
            if live is not None:
                raise BadInput(f"{opt} {out}: a launched run is writing its record there (pid {live}); "
                               f"choose another directory")
            db = out / "run.db"
            if db.exists():
                mode = record_mode(db)
                if mode is None or (self.replaces is not None and mode not in self.replaces):
                    what = "not a run record" if mode is None else f"the record of a launched run (mode {mode})"
                    raise BadInput(f"{opt} {out}: {db.name} there is {what}, which {self.what} does not "
                                   f"replace; choose another directory")
        except BaseException:
            with contextlib.suppress(OSError):  # (refused: the lock file goes too, removed while still held)
                path.unlink()
            fh.close()
            raise
        fh.seek(0)
        fh.truncate()
        fh.write(json.dumps({"pid": os.getpid()}) + "\n")
        fh.flush()
        self._fh = fh

    def release(self) -> None:
        """Give OUTDIR back: the lock file goes (removed while still held; see acquire)."""
        if self._fh is not None:
            with contextlib.suppress(OSError):
                (self.out / LOCK_FILE).unlink()
            self._fh.close()
            self._fh = None

    def __enter__(self) -> RecordClaim:
        self.acquire()
        return self

    def __exit__(self, *_: object) -> None:
        self.release()


LATEST = "latest"  # RUNS/latest: a link to the newest launch's directory


def new_run_dir(runs: Path, now: float | None = None) -> Path:
    """A launch's own directory when no -o is given: RUNS/YYYYMMDD-HHMMSS (-2, -3, ... if taken), not yet made;
    every run keeps its record."""
    import time

    stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime(now))
    path, n = runs / stamp, 1
    while path.exists() or path.is_symlink():
        n += 1
        path = runs / f"{stamp}-{n}"
    return path


def link_latest(run_dir: Path) -> Path:
    """Point RUNS/latest (beside run_dir) at run_dir. A real directory there (a record from before runs had
    their own directories) is kept under RUNS/latest-<its time>."""
    import time

    latest = run_dir.parent / LATEST
    if latest.is_dir() and not latest.is_symlink():
        stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime(latest.stat().st_mtime))
        kept = latest.with_name(f"{LATEST}-{stamp}")
        latest.rename(kept if not kept.exists() else kept.with_name(f"{kept.name}-{os.getpid()}"))
    tmp = latest.with_name(f".{LATEST}-{os.getpid()}")
    tmp.unlink(missing_ok=True)
    tmp.symlink_to(run_dir.name)
    tmp.replace(latest)  # (atomic: a reader sees the old link or the new one)
    return latest
