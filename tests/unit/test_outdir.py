"""OUTDIR claims (reconswarm_bringup/outdir.py) and reader outputs (reconswarm/cli/outputs.py): who may replace
which run.db."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from reconswarm.cli.outputs import not_the_input
from reconswarm.errors import BadInput
from reconswarm.record.store import RunWriter
from reconswarm.scenario.generate import generate
from reconswarm_bringup.outdir import RecordClaim, record_mode


def _record(d: Path, mode: str) -> Path:
    s = generate(3, 1, 1)
    w = RunWriter(d / "run.db", s, mode)
    w.tick(0, 0.0, s.starts.copy(), s.headings.copy(), np.ones(3, dtype=bool), 1.0, 1.0, 1.0, 1)
    w.close(finished="1")
    return d / "run.db"


def test_a_held_claim_refuses_a_second_writer(tmp_path: Path) -> None:
    with RecordClaim(tmp_path), pytest.raises(BadInput, match="another run is writing its record there"):
        RecordClaim(tmp_path).acquire()
    with RecordClaim(tmp_path):  # released: free again
        pass


@pytest.mark.parametrize("mode, sim_may, launcher_may", [("inprocess", True, True), ("lockstep", False, True),
                                                         ("realtime", False, True)])
def test_who_may_replace_which_record(tmp_path: Path, mode: str, sim_may: bool, launcher_may: bool) -> None:
    _record(tmp_path, mode)
    assert record_mode(tmp_path / "run.db") == mode
    for claim, may in ((RecordClaim(tmp_path), sim_may), (RecordClaim(tmp_path, replaces=None), launcher_may)):
        if may:
            claim.acquire()
            claim.release()
        else:
            with pytest.raises(BadInput, match=f"mode {mode}"):
                claim.acquire()


def test_nobody_replaces_what_is_not_a_record(tmp_path: Path) -> None:
    (tmp_path / "run.db").write_bytes(b"my thesis, misnamed")
    for claim in (RecordClaim(tmp_path), RecordClaim(tmp_path, replaces=None)):
        with pytest.raises(BadInput, match="not a run record"):
            claim.acquire()
    assert (tmp_path / "run.db").read_bytes() == b"my thesis, misnamed"


def test_an_output_that_is_the_input_is_refused(tmp_path: Path) -> None:
    db = _record(tmp_path, "inprocess")
    (tmp_path / "sub").mkdir()
    for out in (db, tmp_path / "sub" / ".." / "run.db", Path(f"{db}-wal")):
        with pytest.raises(BadInput, match="is the record this command reads"):
            not_the_input("-o", out, db)
    not_the_input("-o", tmp_path / "other.csv", db)  # another file: fine
