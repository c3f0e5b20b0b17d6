"""The docs stand alone and the code's pointers hold: every relative link in README.md, CHANGELOG.md and
docs/*.md resolves to a file (and #anchor) inside the repository, no doc sends a reader outside it, and
every repository path named in the code's docstrings and comments exists."""

from __future__ import annotations

import re
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = sorted([ROOT / "README.md", ROOT / "CHANGELOG.md", *(ROOT / "docs").glob("*.md")])

LINK = re.compile(r"!?\[(?:[^\]\[]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
FENCE = re.compile(r"^\s*(```|~~~)")
HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")
EXTERNAL = ("http://", "https://", "mailto:", "ws://")


def _prose(text: str) -> list[str]:
    """The lines outside fenced code blocks (a link or heading inside one is code, not markdown)."""
    out, fenced = [], False
    for line in text.splitlines():
        if FENCE.match(line):
            fenced = not fenced
            continue
        if not fenced:
            out.append(line)
    return out


def _strip_code_spans(line: str) -> str:
    return re.sub(r"`[^`]*`", "", line)


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: markup dropped, lower case, punctuation removed, spaces to hyphens."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link's text stays
    text = text.replace("`", "").replace("*", "").lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(md: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for line in _prose(md.read_text()):
        m = HEADING.match(line)
        if not m:
            continue
        base = slug(m.group(2))
        n = seen.get(base, 0)
        seen[base] = n + 1
        out.add(base if n == 0 else f"{base}-{n}")
    return out


def links(md: Path) -> list[str]:
    return [m.group(1) for line in _prose(md.read_text()) for m in LINK.finditer(_strip_code_spans(line))]


def test_the_docs_exist():
    names = {p.name for p in DOCS}
    assert {"README.md", "CHANGELOG.md", "paper.md", "scenario.md", "architecture.md", "wire.md", "faults.md",
            "ros2.md", "foxglove.md", "sweeps.md", "benchmarks.md", "security.md"} <= names, sorted(names)


def test_the_slug_rule():
    assert slug("Live view (Foxglove WebSocket)") == "live-view-foxglove-websocket"
    assert slug("ROS 2 mode (`--ros2`)") == "ros-2-mode---ros2"
    assert slug("Wire protocol (Zenoh, msgpack, `\"v\": 1`)") == "wire-protocol-zenoh-msgpack-v-1"


@pytest.mark.parametrize("md", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_resolves_inside_the_repository(md: Path):
    if not md.exists():
        pytest.fail(f"{md.relative_to(ROOT)} is missing")
    bad = []
    for target in links(md):
        if target.startswith(EXTERNAL):
            continue
        path_part, _, anchor = target.partition("#")
        dest = (md.parent / path_part).resolve() if path_part else md
        if dest != ROOT and ROOT not in dest.parents:
            bad.append(f"{target}: outside the repository")
            continue
        if not dest.exists():
            bad.append(f"{target}: no such file")
            continue
        if anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            bad.append(f"{target}: no heading with anchor #{anchor} in {dest.relative_to(ROOT)}")
    assert bad == [], f"{md.relative_to(ROOT)}: " + "; ".join(bad)


@pytest.mark.parametrize("md", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_doc_sends_a_reader_outside_the_repository(md: Path):
    """Users never see the developers' shared folder: no `shared/spec/...`, `../shared/...` or a bare
    INTERFACES.md / PAPER_NOTES.md (the docs that hold their content are docs/wire.md, docs/scenario.md and
    docs/paper.md)."""
    text = md.read_text()
    found = re.findall(r"shared/spec|\.\./shared|shared/tools|INTERFACES\.md|PAPER_NOTES(?:\.md)?", text)
    assert found == [], f"{md.relative_to(ROOT)} names {sorted(set(found))}"


# ------------------------------------------------------------------------ repository paths in the code

SCANNED = ("reconswarm", "agent", "simworld", "monitor", "reconswarm_bringup", "tests", "bench", "deploy", "docs")
TOP = ("reconswarm", "reconswarm_bringup", "agent", "simworld", "monitor", "tests", "bench", "deploy", "docs")
# A token that starts at a top-level directory of the repository and continues with a path: `agent/brain.py`,
# `reconswarm/net/`, `tests/system/faults/test_secure.py`. Not preceded by a path or key character, so key
# expressions (`swarm/<run>/agent/<id>/state`, `R/agent/i/cmd`) and URLs are not taken for paths.
PATH_TOKEN = re.compile(r"(?<![\w./<>*{}$-])((?:" + "|".join(TOP) + r")/[\w./*-]*[\w/*])")
# Paths the code names that are not in the repository, each for a reason (outputs a run writes, such as
# runs/latest/run.db, do not start at a source directory and are not taken for paths in the first place):
NOT_IN_REPO: set[str] = set()
# A path in another project's repository, named with it ("rmw_zenoh's docs/design.md"): theirs, not ours.
OTHER_REPOSITORIES = ("rmw_zenoh",)


KINDS = {tokenize.COMMENT, tokenize.STRING, getattr(tokenize, "FSTRING_MIDDLE", tokenize.STRING)}


def _comments_and_docstrings(path: Path) -> list[tuple[int, str]]:
    """(line number, text) of every comment and string literal of a Python file (docstrings, help texts
    and messages all name paths for a reader)."""
    out = []
    with path.open("rb") as f:
        for tok in tokenize.tokenize(f.readline):
            if tok.type in KINDS:
                out.append((tok.start[0], tok.string))
    return out


def _as_file(token: str) -> str:
    """`simworld/ros2_io.Ros2World` (a module and a name in it) -> `simworld/ros2_io.py`."""
    stem, dot, attr = token.rpartition(".")
    module = ROOT / f"{stem}.py"
    if dot and "/" not in attr and attr.isidentifier() and attr not in ("py", "md", "sh", "toml") and module.exists():
        return f"{stem}.py"
    return token


def _key_fragment(token: str) -> bool:
    """`agent/1/`, `agent/3/state`: a key with an id in it, not a path (no file or folder of the repository
    has a name starting with a digit)."""
    return any(part[:1].isdigit() for part in token.split("/")[1:])


def _exists(token: str) -> bool:
    """A path, or a glob pattern (`reconswarm_bringup/cli*.py`) that matches something."""
    if "*" in token:
        return next(ROOT.glob(token), None) is not None
    return (ROOT / token).exists()


def _named_paths() -> list[tuple[str, int, str]]:
    found = []
    for top in SCANNED:
        for py in sorted((ROOT / top).rglob("*.py")):
            if ".venv" in py.parts or py == Path(__file__).resolve():  # this file's strings are test cases
                continue
            for line, text in _comments_and_docstrings(py):
                for m in PATH_TOKEN.finditer(text):
                    if any(repo in text[max(0, m.start() - 40):m.start()] for repo in OTHER_REPOSITORIES):
                        continue
                    if _key_fragment(m.group(1)):
                        continue
                    found.append((str(py.relative_to(ROOT)), line, _as_file(m.group(1))))
    return found


def test_the_path_scanner_sees_paths_and_not_keys():
    assert PATH_TOKEN.findall("see agent/brain.py and reconswarm/net/ (eq. 3)") == ["agent/brain.py",
                                                                                    "reconswarm/net/"]
    assert PATH_TOKEN.findall("swarm/<run>/agent/<id>/state, R/agent/i/cmd, runs/latest/run.db") == []
    assert PATH_TOKEN.findall("tests/system/faults/test_secure.py::test_x.") == ["tests/system/faults/test_secure.py"]
    assert PATH_TOKEN.findall("(reconswarm_bringup/cli*.py)") == ["reconswarm_bringup/cli*.py"]
    assert _exists("reconswarm_bringup/cli*.py") and not _exists("reconswarm_bringup/nothing*.py")
    assert _key_fragment("agent/1/") and _key_fragment("agent/3/state") and not _key_fragment("agent/brain.py")
    assert _as_file("simworld/ros2_io.Ros2World") == "simworld/ros2_io.py"
    assert _as_file("agent/brain.py") == "agent/brain.py"
    assert _as_file("agent/nothing.Here") == "agent/nothing.Here"


def test_every_repository_path_named_in_the_code_exists():
    named = _named_paths()
    assert len(named) > 50, "the scanner found almost nothing: the pattern is broken"
    missing = [f"{where}:{line}: {token}" for where, line, token in named
               if token not in NOT_IN_REPO and not _exists(token)]
    assert missing == [], "paths named in the code that do not exist:\n" + "\n".join(missing)


def test_the_code_sends_no_reader_outside_the_repository():
    """Docstrings, comments and help texts point at the project's own docs, not at files a clone lacks."""
    outside = re.compile(r"shared/spec|\.\./shared|INTERFACES\.md|PAPER_NOTES")
    found = []
    for top in SCANNED:
        for f in sorted((ROOT / top).rglob("*")):
            if f.suffix not in (".py", ".sh", ".toml") or ".venv" in f.parts or f == Path(__file__).resolve():
                continue
            found += [f"{f.relative_to(ROOT)}:{n}" for n, line in enumerate(f.read_text().splitlines(), 1)
                      if outside.search(line)]
    found += [f"pyproject.toml:{n}" for n, line in enumerate((ROOT / "pyproject.toml").read_text().splitlines(), 1)
              if outside.search(line)]
    assert found == []
