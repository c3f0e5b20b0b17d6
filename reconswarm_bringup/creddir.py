"""The directory `reconswarm credentials DEPLOYMENT.toml -o DIR` writes: it touches only what it made itself.

DIR is new (made 0700, with each host's directory), empty (used as it is: its mode is the user's), or a
previous output of the same deployment (the same `run` and the same host names): DIR/credentials.json, which
the command writes first, lists every host's directory and file it makes. A previous output is replaced only
if it holds nothing else: every entry of DIR is that list or a host's directory (a real directory, not a
symbolic link), and every entry of a host's directory a regular file the list names. Then its listed files
are deleted (and no earlier host's keys of another CA stay behind) and the new ones written, each opened
without following a symbolic link. Anything else is refused before anything is touched: one line naming
the path (BadInput, exit 2).
"""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

from reconswarm.errors import BadInput

MANIFEST = "credentials.json"
WRITER = "reconswarm credentials"
_FRESH = "give an empty or new directory"


def prepare(out: Path, run: str, files: dict[str, list[str]], option: str = "-o") -> None:
    """Make `out` ready for a deployment's credentials: files[host] = the names written in out/<host>/."""
    try:
        st = os.lstat(out)
    except FileNotFoundError:
        st = None
    except OSError as exc:
        raise BadInput(f"{option} {out}: cannot write there ({exc.strerror or exc})") from None
    try:
        if st is None:
            out.mkdir(mode=0o700, parents=True)
        elif not stat.S_ISDIR(st.st_mode):
            raise BadInput(f"{option} {out}: not a directory")
        elif any(out.iterdir()):
            _previous(out, run, set(files), option)
            _clear_previous(out)
        _write_manifest(out, run, files)
        for host in files:
            if not (out / host).is_dir():
                (out / host).mkdir(mode=0o700)
    except OSError as exc:
        raise BadInput(f"{option} {out}: cannot write there ({exc.strerror or exc})") from None


def _previous(out: Path, run: str, hosts: set[str], option: str) -> dict[str, set[str]]:
    """The files a previous output of the same deployment in `out` lists per host; BadInput for anything else."""
    m = out / MANIFEST
    try:
        if not stat.S_ISREG(os.lstat(m).st_mode):
            raise OSError
        doc = json.loads(m.read_text())
        assert isinstance(doc, dict) and doc.get("written_by") == WRITER
        old_run, listed = doc["run"], doc["hosts"]
        assert isinstance(listed, dict) and all(isinstance(v, list) for v in listed.values())
        old = {str(h): {str(f) for f in v} for h, v in listed.items()}
    except (OSError, ValueError, KeyError, AssertionError):
        raise BadInput(f"{option} {out}: not empty, and not a directory {WRITER} wrote (no {MANIFEST} of its "
                       f"own): {_FRESH}") from None
    if old_run != run or set(old) != hosts:
        raise BadInput(f"{option} {out}: holds the credentials of another deployment (run {old_run!r}, hosts "
                       f"{', '.join(sorted(old))}): {_FRESH}")
    for entry in out.iterdir():
        if entry.name == MANIFEST:
            continue
        mode = os.lstat(entry).st_mode
        if stat.S_ISLNK(mode):
            raise BadInput(f"{option} {out}: {entry} is a symbolic link, not a directory {WRITER} made: {_FRESH}")
        if entry.name not in old or not stat.S_ISDIR(mode):
            raise BadInput(f"{option} {out}: {entry} is not something {WRITER} wrote: move it away or {_FRESH}")
        for f in entry.iterdir():
            if f.name not in old[entry.name] or not stat.S_ISREG(os.lstat(f).st_mode):
                raise BadInput(f"{option} {out}: {f} is not a file {WRITER} wrote: move it away or {_FRESH}")
    return old


def _clear_previous(out: Path) -> None:
    """Delete a previous output's files (each checked by _previous: a regular file its list names, in a real
    directory of one of its hosts), keeping the directories."""
    for entry in out.iterdir():
        if entry.name != MANIFEST:
            for f in entry.iterdir():
                f.unlink()
    (out / MANIFEST).unlink()


def _write_manifest(out: Path, run: str, files: dict[str, list[str]]) -> None:
    data = json.dumps({"written_by": WRITER, "run": run, "hosts": files}, indent=2) + "\n"
    fd = os.open(out / MANIFEST, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
    try:
        os.write(fd, data.encode())
    finally:
        os.close(fd)
