"""Output paths a command is asked to write, checked before anything starts. Each check raises BadInput with one
line naming the option and the path (exit 2)."""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

from reconswarm.errors import BadInput


def _why(exc: OSError) -> str:
    # (mkdir -p through a path where a file stands says "File exists")
    return "a file stands where a directory should be" if isinstance(exc, FileExistsError) else exc.strerror or str(exc)


def _probe(directory: Path) -> None:
    directory.mkdir(parents=True, exist_ok=True)
    fd, probe = tempfile.mkstemp(prefix=".write-probe-", dir=directory)
    os.close(fd)
    os.unlink(probe)


def writable_dir(option: str, path: Path) -> None:
    """Create the directory if needed and make sure a file can be written in it."""
    try:
        _probe(path)
    except OSError as exc:
        raise BadInput(f"{option} {path}: cannot write there ({_why(exc)})") from None


def creatable_dir(option: str, path: Path) -> None:
    """The directory exists and is writable, or can be made: checked without creating anything (a refused command
    leaves no directory behind)."""
    probe = path.absolute()
    while not probe.exists():
        if probe.is_symlink():  # (a dangling link: mkdir would fail on it)
            raise BadInput(f"{option} {path}: cannot write there ({probe} is a broken symbolic link)")
        probe = probe.parent
    if not probe.is_dir():
        raise BadInput(f"{option} {path}: cannot write there (a file stands where a directory should be)")
    try:  # (a file made and removed in the nearest directory there is: what the kernel says, e.g. a read-only mount)
        fd, name = tempfile.mkstemp(prefix=".write-probe-", dir=probe)
        os.close(fd)
        os.unlink(name)
    except OSError as exc:
        raise BadInput(f"{option} {path}: cannot write there ({_why(exc)})") from None


def writable_file(option: str, path: Path) -> None:
    """The file can be created: not a directory, and its directory exists (or can be made) and is writable."""
    if path.is_dir():
        raise BadInput(f"{option} {path}: is a directory")
    try:
        _probe(path.parent)
    except OSError as exc:
        raise BadInput(f"{option} {path}: cannot write there ({_why(exc)})") from None


def same_file(a: Path, b: Path) -> bool:
    """True if a and b name one file (the same inode if both exist, else the same resolved path)."""
    with contextlib.suppress(OSError):
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    return a.resolve() == b.resolve()


def not_the_input(option: str, out: Path, *inputs: Path) -> None:
    """Refuse writing `out` when it is one of the files the command reads (or their WAL companions)."""
    for src in inputs:
        for companion in (src, Path(f"{src}-wal"), Path(f"{src}-shm")):
            if same_file(out, companion):
                raise BadInput(f"{option} {out}: is the record this command reads ({src}); "
                               f"write to another file")
