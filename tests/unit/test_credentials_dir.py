"""`reconswarm credentials DEPLOYMENT.toml -o DIR` touches only what it made itself (reconswarm_bringup/creddir.py):
it never changes the mode of a DIR it did not make, never follows a host directory that is a symbolic link,
never deletes a file of the user's, and never leaves an earlier deployment's keys of another CA beside its own;
each is refused with one line naming the path, exit 2, before anything is touched."""

from __future__ import annotations

import os
import stat
from pathlib import Path

from typer.testing import CliRunner

from reconswarm_bringup.cli import app

DEP = """
run = "paper"
world = "A"
monitor = "A"
{hosts}
"""
HOST = """
[[host]]
name = "{name}"
router = "tls/10.0.0.{n}:7450"
agents = [{agents}]
"""


def deployment(tmp: Path, hosts: dict[str, str], name: str = "dep.toml") -> Path:
    text = DEP.format(hosts="".join(HOST.format(name=h, n=i + 1, agents=a) for i, (h, a) in enumerate(hosts.items())))
    p = tmp / name
    p.write_text(text)
    return p


def credentials(dep: Path, out: Path) -> tuple[int, list[str]]:
    r = CliRunner().invoke(app, ["credentials", str(dep), "-o", str(out)])
    return r.exit_code, r.output.strip().splitlines()


def refused(dep: Path, out: Path, path: Path) -> str:
    code, lines = credentials(dep, out)
    assert code == 2, lines
    assert len(lines) == 1 and str(path) in lines[0] and "Traceback" not in lines[0], lines
    return lines[0]


def tree(d: Path) -> dict[str, tuple[int, bytes | str]]:
    """Every path under d (not following links) with its mode and content (a link: its target)."""
    out: dict[str, tuple[int, bytes | str]] = {}
    for root, dirs, files in os.walk(d):
        for n in dirs + files:
            p = Path(root) / n
            st = os.lstat(p)
            body: bytes | str = os.readlink(p) if p.is_symlink() else p.read_bytes() if p.is_file() else b""
            out[str(p.relative_to(d))] = (st.st_mode, body)
    return out


def test_an_empty_directory_keeps_its_mode(tmp_path: Path) -> None:
    out = tmp_path / "shared"
    out.mkdir()
    os.chmod(out, 0o1777)
    code, lines = credentials(deployment(tmp_path, {"A": "1, 2"}), out)
    assert code == 0, lines
    assert stat.S_IMODE(out.stat().st_mode) == 0o1777
    assert stat.S_IMODE((out / "A").stat().st_mode) == 0o700 and (out / "A" / "agent-1-key.pem").is_file()


def test_a_new_directory_is_made_private(tmp_path: Path) -> None:
    out = tmp_path / "new" / "creds"
    code, lines = credentials(deployment(tmp_path, {"A": "1"}), out)
    assert code == 0, lines
    assert stat.S_IMODE(out.stat().st_mode) == 0o700


def test_a_host_directory_that_is_a_symbolic_link_is_not_followed(tmp_path: Path) -> None:
    dep = deployment(tmp_path, {"A": "1", "B": "2"})
    out = tmp_path / "creds"
    assert credentials(dep, out)[0] == 0
    keys = tmp_path / "keys"  # the user's own directory of keys
    keys.mkdir(mode=0o755)
    (keys / "important.pem").write_text("mine")
    (keys / "service.json5").write_text("{}")
    for f in (out / "B").iterdir():
        f.unlink()
    (out / "B").rmdir()
    (out / "B").symlink_to(keys)
    before = tree(keys)
    refused(dep, out, out / "B")
    assert tree(keys) == before and stat.S_IMODE(keys.stat().st_mode) == 0o755
    # nor in a directory it never wrote
    other = tmp_path / "other"
    other.mkdir()
    (other / "A").symlink_to(keys)
    refused(dep, other, other)
    assert tree(keys) == before


def test_a_users_file_in_a_host_directory_is_kept(tmp_path: Path) -> None:
    dep = deployment(tmp_path, {"A": "1"})
    out = tmp_path / "creds"
    assert credentials(dep, out)[0] == 0
    (out / "A" / "important.pem").write_text("mine")
    before = tree(out)
    refused(dep, out, out / "A" / "important.pem")
    assert tree(out) == before
    # a directory of the user's that the command never wrote: refused whatever is in it
    mine = tmp_path / "mine"
    (mine / "A").mkdir(parents=True)
    (mine / "A" / "ca.pem").write_text("my CA")
    before = tree(mine)
    refused(dep, mine, mine)
    assert tree(mine) == before


def test_another_deployments_keys_are_not_left_beside_new_ones(tmp_path: Path) -> None:
    out = tmp_path / "creds"
    assert credentials(deployment(tmp_path, {"A": "1", "B": "2"}), out)[0] == 0
    before = tree(out)
    line = refused(deployment(tmp_path, {"A": "1, 2"}, "dep2.toml"), out, out)
    assert "another deployment" in line
    assert tree(out) == before


def test_the_same_deployment_is_written_again_in_place(tmp_path: Path) -> None:
    """Its own previous output is replaced whole: new keys of a new CA, no file of an agent it no longer has."""
    out = tmp_path / "creds"
    assert credentials(deployment(tmp_path, {"A": "1, 2"}), out)[0] == 0
    ca = (out / "A" / "ca.pem").read_bytes()
    code, lines = credentials(deployment(tmp_path, {"A": "1"}, "dep2.toml"), out)
    assert code == 0, lines
    assert (out / "A" / "ca.pem").read_bytes() != ca
    assert not list((out / "A").glob("agent-2*")) and (out / "A" / "agent-1-key.pem").is_file()
