"""The monitor's end against its own record (issue 20): an end clock that the world's next clock contradicts,
or a "converged" that the truth contradicts, is refused (a `RefusedEnd` output: the process counts it as an
intrusion of the session that claimed it) and the recording goes on; a conflicting command reported by the
world makes the run not deterministic. MonitorNode driven by hand, a real run.db; and the launcher's view of the
clock (its faults fire on it), which believes a claimed end only until the world ticks on."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from reconswarm.net.wire import wire
from reconswarm.record.summary import summarize
from reconswarm_bringup.clockwatch import ClockFollow
from tests.unit.monitor_run import DT, S, clock, started, truth, world, world_report


def at_target() -> np.ndarray:
    return np.asarray(S.target_m) + S.offsets  # every head point on its slot: converged


def test_a_converged_end_the_truth_contradicts_is_refused_and_recording_goes_on(tmp_path: Path) -> None:
    run = started(tmp_path)
    for k in range(5):
        run.tick(k, 0.01 * k)
    run.step(0.06, clock(5, end=True, reason="converged"), truth(5))  # the swarm at its start, far from converged
    assert run.exit is None and run.node.end is None
    (refused,) = run.refused
    assert refused.source == "world-zid" and "not converged" in refused.why
    for k in range(6, 9):
        run.tick(k, 0.01 * k)
    run.step(0.1, clock(9, end=True, reason="duration"), truth(9))  # the world's own end
    assert run.exit is None  # its tick is in, but the world has not gone
    run.step(0.2, world(False))  # the world closes its session after its end
    assert run.exit is not None and run.exit.reason == "recorded"
    with run.record() as rec:
        s = summarize(rec)
    assert (s["end_reason"], s["converged"], s["ticks"]) == ("duration", False, 10)


def test_an_end_the_worlds_next_clock_contradicts_is_refused(tmp_path: Path) -> None:
    run = started(tmp_path)
    run.tick(0, 0.0)
    run.step(0.01, clock(1, end=True, reason="stopped", source="forger"), truth(1))
    assert run.exit is None and run.refused == []  # its tick is in, but the world has not gone
    run.step(0.03, clock(1))  # the world ticks on
    assert run.node.end is None
    (refused,) = run.refused
    assert refused.source == "forger" and "goes on" in refused.why
    run.tick(2, 0.04)
    assert run.exit is None


def test_an_end_claiming_a_far_tick_is_refused_by_the_worlds_next_clock(tmp_path: Path) -> None:
    """A forged end may claim any tick: one far ahead is refuted by the world's next clock all the same (it was
    believed until `end_grace_s` passed, then closed the record as ended while the world went on)."""
    run = started(tmp_path)
    run.tick(0, 0.0)
    run.step(0.01, clock(4000, end=True, reason="duration"))
    run.tick(1, 0.05)  # the world ticks on, far before tick 4000
    (refused,) = run.refused
    assert run.node.end is None and "goes on" in refused.why
    for k in range(2, 100):  # longer than end_grace_s (3 s) of wall time
        run.tick(k, 0.05 * k)
    assert run.exit is None


def test_a_real_converged_end_stands(tmp_path: Path) -> None:
    run = started(tmp_path)
    run.tick(0, 0.0)
    run.step(0.01, clock(1, end=True, reason="converged"), truth(1, at_target()))
    assert run.exit is None  # the world's token has not gone yet
    run.step(0.3, world(False))
    assert run.exit is not None and run.refused == []
    with run.record() as rec:
        s = summarize(rec)
    assert (s["end_reason"], s["converged"]) == ("converged", True)


def test_a_conflicting_command_makes_lockstep_not_deterministic(tmp_path: Path) -> None:
    run = started(tmp_path)
    for k in range(4):
        run.tick(k, 0.01 * k)
    run.step(0.05, world_report((("conflicting_command", "stranger", 1, 2 * DT),)))
    run.stop(0.1)
    with run.record() as rec:
        s = summarize(rec)
    assert (s["deterministic"], s["determinism_lost_at_s"]) == (False, round(2 * DT, 9))


def test_a_converged_end_whose_tick_never_comes_is_judged_at_the_last_tick_recorded(tmp_path: Path) -> None:
    run = started(tmp_path)
    run.tick(0, 0.0)
    run.step(0.1, clock(2, end=True, reason="converged"))
    assert run.refused == []  # its tick not in yet
    run.step(3.2)
    assert run.exit is None and run.node.end is None  # the grace is over: the record is not converged
    assert "not converged" in run.refused[0].why


def test_the_launcher_believes_a_claimed_end_only_until_the_world_ticks_on(caplog: pytest.LogCaptureFixture) -> None:
    """The launcher's clock view (faults fire on it): a forged end with the world's id is refuted by the world's
    next clock, and the view follows the world again; the world's own end stands."""
    f = ClockFollow()
    for k in range(4):
        f.take(wire.Clock(k, 0.05 * k, (1, 2, 3)))
    forged = wire.Clock(4, 0.2, (1, 2, 3), end=True, reason="converged")
    f.take(forged)
    assert f.end == forged and f.k == 3  # (the view stays at the last tick)
    f.take(wire.Clock(4, 0.2, (1, 2)))  # the world's tick 4: it did not end
    assert f.end is None and f.refuted == 1 and (f.k, f.t, f.alive) == (4, 0.2, 2)
    f.take(wire.Clock(2, 0.1, (1, 2, 3)))  # a stale clock does not move the view back
    assert (f.k, f.alive) == (4, 2)
    far = wire.Clock(4000, 200.0, (1, 2), end=True, reason="duration")  # a forged end may claim any tick
    f.take(far)
    f.take(wire.Clock(5, 0.25, (1, 2)))
    assert f.end is None and f.refuted == 2
    said = [r.getMessage().split(" was not the world's: ") for r in caplog.records]
    assert said == [["a claimed end of the mission (tick 4, 'converged')", "its clock went on at tick 4"],
                    ["a claimed end of the mission (tick 4000, 'duration')", "its clock went on at tick 5"]]
    own = wire.Clock(6, 0.3, (1, 2), end=True, reason="duration")
    f.take(own)
    assert f.end == own and (f.k, f.alive) == (5, 2)
