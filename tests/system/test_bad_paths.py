"""No traceback for a bad path in any command (issue 21, friction 1): a file where a directory should be,
a directory where a file should be, a directory that cannot be made, a missing input. Each is one line
naming the option or file, exit 2. `scenario generate -o DIR/FILE` makes a missing DIR, as docs/sweeps.md's
sweep recipe expects."""

from __future__ import annotations

from pathlib import Path

import pytest

from reconswarm.scenario.generate import generate
from reconswarm.scenario.model import load, to_toml
from tests.support import reconswarm

pytestmark = pytest.mark.parallel  # (no launch, no router, no wall-clock bound: beside the unit tests)


@pytest.fixture(scope="module")
def place(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("paths")
    (d / "afile").write_text("x")
    (d / "adir").mkdir()
    (d / "g.toml").write_text(to_toml(generate(3, 1, 1)))
    r = reconswarm("sim", str(d / "g.toml"), "-o", str(d / "rec"), "--json")
    assert r.returncode == 0, r.stderr
    return d


CASES = [
    ("scenario", "generate", "-n", "3", "-o", "{afile}/x.toml"),
    ("scenario", "generate", "-n", "3", "-o", "{adir}"),
    ("scenario", "generate", "-n", "3", "-o", "/proc/nope/x.toml"),
    ("scenario", "check", "{missing}"),
    ("scenario", "check", "{adir}"),
    ("sim", "{missing}"),
    ("sim", "{adir}"),
    ("sim", "{g}", "-o", "{afile}"),
    ("sim", "{g}", "-o", "{afile}/x"),
    ("sweep", "{g}", "-o", "{afile}"),
    ("sweep", "{adir}", "-o", "{adir}/sw"),
    ("monitor", "summary", "{missing}"),
    ("monitor", "summary", "{adir}"),
    ("monitor", "events", "{afile}"),
    ("monitor", "export", "{rec}", "-o", "{adir}"),
    ("monitor", "export", "{rec}", "-o", "{afile}/x.csv"),
    ("monitor", "export", "{rec}", "--format", "mcap", "-o", "{afile}/x.mcap"),
    ("monitor", "plot", "{rec}", "-o", "{afile}/x.png"),
    ("monitor", "plot", "{missing}", "-o", "{adir}/x.png"),
    ("monitor", "animate", "{rec}", "-o", "{afile}/x.gif"),
    ("monitor", "record", "--scenario", "{g}", "--db", "{afile}/x.db", "--connect", "tcp/127.0.0.1:9"),
    ("monitor", "record", "--scenario", "{g}", "--db", "{adir}", "--connect", "tcp/127.0.0.1:9"),
    ("monitor", "record", "--scenario", "{missing}", "--db", "{adir}/x.db", "--connect", "tcp/127.0.0.1:9"),
]


@pytest.mark.parametrize("args", CASES, ids=lambda a: " ".join(a))
def test_a_bad_path_is_one_line_exit_2(place: Path, args: tuple[str, ...]) -> None:
    names = {"afile": place / "afile", "adir": place / "adir", "missing": place / "missing.toml",
             "g": place / "g.toml", "rec": place / "rec" / "run.db"}
    argv = [a.format(**{k: str(v) for k, v in names.items()}) for a in args]
    r = reconswarm(*argv, timeout=60)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1 and "Traceback" not in r.stderr, lines


def test_generate_makes_the_missing_directory(tmp_path: Path) -> None:
    out = tmp_path / "gen" / "deeper" / "g12.toml"
    r = reconswarm("scenario", "generate", "--agents", "12", "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert len(load(out).agents) == 12
