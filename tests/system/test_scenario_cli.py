"""Scenario files as a user meets them: `reconswarm scenario check|generate` and `sim` as separate processes."""

from __future__ import annotations

import pytest

from reconswarm.scenario.generate import generate
from reconswarm.scenario.model import check, parse
from tests.support import PAPER
from tests.support import reconswarm as cli
from tests.unit import test_scenario as unit
from tests.unit.test_scenario import BAD, CHECK_IN_SUBPROCESS, sub

pytestmark = pytest.mark.parallel  # (no launch, no router, no wall-clock bound: beside the unit tests)

bad_files = unit.bad_files  # the same files as the in-process table (a module-scoped fixture)


@pytest.mark.parametrize("name", CHECK_IN_SUBPROCESS)
def test_scenario_check_cli_refuses(bad_files, name):
    field = dict((b[0], b[2]) for b in BAD)[name]
    f = bad_files[name]
    r = cli("scenario", "check", str(f))
    assert r.returncode == 2, r.stderr
    lines = r.stderr.splitlines()
    assert len(lines) == 1, r.stderr  # exactly one line ...
    assert "Traceback" not in r.stderr  # ... and no traceback
    assert str(f) in lines[0] and f": {field}: " in lines[0], lines[0]  # naming the file and the field
    assert r.stdout == ""


@pytest.mark.parametrize("name", ["unknown-key", "nan", "non-convex", "agents-overlapping", "bad-planner-kind"])
def test_sim_cli_refuses_without_traceback(bad_files, tmp_path, name):
    """As a user meets it: a separate process, exit 2, one line, no traceback."""
    field = dict((b[0], b[2]) for b in BAD)[name]
    out = tmp_path / "run"
    r = cli("sim", str(bad_files[name]), "-o", str(out), "--json")
    assert r.returncode == 2, r.stderr
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert str(bad_files[name]) in lines[0] and f": {field}: " in lines[0]
    assert r.stdout == ""
    assert not (out / "run.db").exists()


def test_check_accepts_the_paper_scenario_without_warnings():
    r = cli("scenario", "check", str(PAPER))
    assert r.returncode == 0 and r.stderr == ""
    assert "10 agents, 3 obstacles" in r.stdout
    s, warns = check(PAPER)
    assert warns == []
    assert [a.id for a in s.agents] == list(range(1, 11))
    assert [o.id for o in s.obstacles] == ["diamond", "hexagon", "triangle"]


def test_assumption_4_1_violation_is_a_warning_not_an_error(tmp_path):
    # Offsets of agents 1 and 2 15.9 m apart, below d_max,12 = 2.60 + 4.58 + 10 = 17.18 m (all others clear).
    f = tmp_path / "close-slots.toml"
    f.write_text(sub("offset_m = [-12.0, 20.78]", "offset_m = [-12.0, 52.0]"))
    r = cli("scenario", "check", str(f))
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    warn = [ln for ln in r.stderr.splitlines() if "Assumption 4.1" in ln]
    assert len(warn) == 1 and str(f) in warn[0] and "agents 1 and 2" in warn[0] and "17.18" in warn[0]
    assert "ok" in r.stdout


def test_sim_with_negative_seed_in_file(tmp_path):
    f = tmp_path / "neg-seed.toml"
    f.write_text(sub("duration_s = 300.0", "duration_s = 1.0", sub("seed = 0", "seed = -1")))
    r = cli("sim", str(f), "-o", str(tmp_path / "run"), "--json")
    assert "Traceback" not in r.stderr
    assert r.returncode == 2
    assert len(r.stderr.splitlines()) == 1 and "scenario.seed" in r.stderr and str(f) in r.stderr


def test_generate_cli_output_passes_check(tmp_path):
    r = cli("scenario", "generate", "--agents", "25", "--obstacles", "4", "--seed", "9")
    assert r.returncode == 0 and r.stderr == ""
    f = tmp_path / "gen.toml"
    f.write_text(r.stdout)
    c = cli("scenario", "check", str(f))
    assert c.returncode == 0 and c.stderr == "", c.stderr
    assert parse(r.stdout) == generate(25, 4, 9)
