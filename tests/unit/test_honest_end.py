"""The monitor's end against its own record (issue 20): an end clock that the world's next clock contradicts,
or a "converged" that the truth contradicts, is refused and the recording goes on; a conflicting command
reported by the world makes the run not deterministic. MonitorNode driven by hand, a real run.db."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from reconswarm.net import wire
from reconswarm.record.store import RunRecord
from reconswarm.record.summary import summarize
from tests.unit.test_monitor_node import DT, IDS, S, node_for, tick, truth


def end_clock(k: int, reason: str) -> wire.Clock:
    return wire.Clock(k, k * DT, tuple(IDS), wire.ClockMode.LOCKSTEP, 0.0, True, reason, 0, {})


def at_target() -> np.ndarray:
    return np.asarray(S.target_m) + S.offsets  # every head point on its slot: converged


def test_a_converged_end_the_truth_contradicts_is_refused_and_recording_goes_on(tmp_path: Path) -> None:
    node = node_for(tmp_path)
    for k in range(5):
        tick(node, k, 0.01 * k)
    node.clock(end_clock(5, "converged"), 0.06, "world-zid")  # stamped with the world's id: admitted
    node.truth(truth(5))  # the swarm at its start, far from converged
    assert node.poll(0.07) is False and node.end is None
    assert node.refused_ends and node.refused_ends[0][0] == "world-zid" and "not converged" in node.refused_ends[0][1]
    for k in range(6, 9):
        tick(node, k, 0.01 * k)
    node.clock(end_clock(9, "duration"), 0.1, "world-zid")  # the world's own end
    node.truth(truth(9))
    node.world_up(False, 0.2)  # the world closes its session after its end
    assert node.poll(0.2) is True
    node.finish(0.3, 0)
    with RunRecord(tmp_path / "run.db") as rec:
        s = summarize(rec)
    assert (s["end_reason"], s["converged"], s["ticks"]) == ("duration", False, 10)


def test_an_end_the_worlds_next_clock_contradicts_is_refused(tmp_path: Path) -> None:
    node = node_for(tmp_path)
    tick(node, 0, 0.0)
    node.clock(end_clock(1, "stopped"), 0.01, "world-zid")
    node.truth(truth(1))
    assert node.poll(0.02) is False  # its tick is in, but the world has not gone
    node.clock(wire.Clock(1, DT, tuple(IDS), wire.ClockMode.LOCKSTEP), 0.03, "world-zid")  # the world ticks on
    assert node.end is None and "goes on" in node.refused_ends[0][1]
    tick(node, 2, 0.04)


def test_a_real_converged_end_stands(tmp_path: Path) -> None:
    node = node_for(tmp_path)
    tick(node, 0, 0.0)
    node.clock(end_clock(1, "converged"), 0.01, "world-zid")
    node.truth(truth(1, at_target()))
    assert node.poll(0.02) is False  # the world's token has not gone yet
    node.world_up(False, 0.3)
    assert node.poll(0.3) is True and node.refused_ends == []
    node.finish(0.4, 0)
    with RunRecord(tmp_path / "run.db") as rec:
        s = summarize(rec)
    assert (s["end_reason"], s["converged"]) == ("converged", True)


def test_a_conflicting_command_makes_lockstep_not_deterministic(tmp_path: Path) -> None:
    node = node_for(tmp_path)
    for k in range(4):
        tick(node, k, 0.01 * k)
    node.conflict(2 * DT)
    node.finish(0.1, 0)
    with RunRecord(tmp_path / "run.db") as rec:
        s = summarize(rec)
    assert (s["deterministic"], s["determinism_lost_at_s"]) == (False, round(2 * DT, 9))


def test_a_converged_end_whose_tick_never_comes_is_judged_at_the_last_tick_recorded(tmp_path: Path) -> None:
    node = node_for(tmp_path)
    tick(node, 0, 0.0)
    node.clock(end_clock(2, "converged"), 0.1, "world-zid")
    assert node.poll(0.1) is False  # its tick not in yet
    assert node.poll(3.2) is False and node.end is None  # the grace is over: the record is not converged
    assert "not converged" in node.refused_ends[0][1]
