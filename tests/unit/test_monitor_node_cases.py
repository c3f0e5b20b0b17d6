"""The monitor's node (monitor/node.py) in the cases its mutation run (bench/mutation.py) found untested: the
world's token as a stall, a world lost on a known clock, ends refused by the world's next clock or by the
truth, the earliest conflicting command, a guess at tick 0, and how the record is closed. Driven by hand
(tests/unit/monitor_run.py): no zenoh, times given, a real run.db."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from monitor.messages import ClockFrom
from reconswarm.net.node import RouterReach, Stop
from reconswarm.paper.events import EventKind
from reconswarm.record.summary import summarize
from tests.unit.monitor_run import (
    DT,
    IDS,
    Run,
    T,
    clock,
    kinds,
    report,
    started,
    token,
    tokens,
    truth,
    world,
    world_report,
)

# ------------------------------------------------------------------------------------------ the world


def test_the_worlds_token_going_is_a_stall_at_once_and_a_world_lost_on_its_last_clock(tmp_path: Path) -> None:
    """The world's token goes 0.3 s after its last clock (tick 3, t = 0.15 s, at wall 1.2345678 s), well within
    world_stall_s: the stall starts then, from that clock; a stop at wall 20.1234567 s records it as lost
    18.889 s long, at t = 0.15 s and Unix time 1020.123457 (offset 1000 s, to the microsecond)."""
    run = started(tmp_path)
    for k in range(3):
        run.tick(k, 0.01 * k)
    run.tick(3, 1.2345678)
    run.step(1.5345678, world(False))
    assert run.node.stall_since == pytest.approx(1.2345678)
    (lost,) = run.stop(20.1234567)
    assert (lost.kind, lost.t, lost.duration_s, lost.wall_unix) == (EventKind.WORLD_LOST, 0.15, 18.889,
                                                                   1020.123457)


def test_a_clock_the_world_put_before_its_token_went_does_not_end_the_stall(tmp_path: Path) -> None:
    """A world killed right after a tick: its token's going can reach the node before that tick's clock (they come
    through different subscribers). The clock 0.036 s later is not the world back (no `world_stalled` of 36 ms);
    one burst_s after the token went, a clock is (the world's own, back)."""
    run = started(tmp_path)
    for k in range(3):
        run.tick(k, 0.05 * k)
    run.step(0.13, world(False))
    assert run.step(0.136, clock(3), truth(3)) == []
    assert run.node.stall_since == pytest.approx(0.1)  # from the last clock before its token went
    (lost,) = run.stop(3.0)
    assert (lost.kind, lost.t, lost.duration_s) == (EventKind.WORLD_LOST, 2 * DT, 2.9)
    with run.record() as rec:
        assert [e["kind"] for e in rec.events()] == ["world_lost"]
    back = started(tmp_path / "back")
    back.tick(0, 0.0)
    back.step(0.1, world(False))
    assert back.step(0.2, clock(1), truth(1)) == []
    (stall,) = back.step(1.1, clock(2), truth(2))  # burst_s after the token went: the world is back
    assert (stall.kind, stall.duration_s) == (EventKind.WORLD_STALLED, 1.1)


def test_the_worlds_token_coming_or_flapping_before_the_start_is_no_stall(tmp_path: Path) -> None:
    run = started(tmp_path)
    run.step(0.1, world(True))
    run.step(0.2, world(False))  # (before the mission's first clock: nothing to stall)
    run.step(0.3, world(True))
    run.tick(0, 0.4)
    run.step(0.5, world(True))  # its token declared again mid-run
    run.tick(1, 0.6)
    assert run.node.stall_since is None
    run.stop(0.7)
    assert run.events == []
    with run.record() as rec:
        assert [e["kind"] for e in rec.events()] == []


def test_a_world_that_stalls_and_comes_back_is_one_event_stamped_on_the_unix_clock(tmp_path: Path) -> None:
    run = started(tmp_path)
    run.tick(0, 0.5)
    run.step(0.6, world(False))
    (stall,) = run.step(3.1234567, world(True), clock(1), truth(1))
    assert (stall.kind, stall.duration_s, stall.wall_unix) == (EventKind.WORLD_STALLED, 2.623, 1003.123457)
    for k in range(2, 8):  # judged burst_s after it is back, and the run goes on
        run.tick(k, 3.2 + 0.5 * k)
    run.stop(7.5)
    with run.record() as rec:
        assert rec.ticks().k.tolist() == list(range(8))


# ------------------------------------------------------------------------------------------ ends


def test_an_end_the_worlds_next_clock_contradicts_is_refused_and_recording_goes_on(tmp_path: Path) -> None:
    """A forger claims the end at tick 2; the world's own clock for tick 2 (no end) refutes it: refused, naming
    the forger, and the run is recorded on, to the world's own end."""
    run = started(tmp_path)
    run.tick(0, 0.0)
    run.tick(1, 0.1)
    run.step(0.15, clock(2, end=True, reason="duration", source="forger-zid"))
    run.tick(2, 0.2)
    (refused,) = run.refused
    assert refused.source == "forger-zid" and "tick 2" in refused.why
    run.tick(3, 0.3)
    run.step(0.4, clock(4, end=True, reason="duration"), truth(4), world(False))
    assert run.exit is not None and run.exit.reason == "recorded" and len(run.refused) == 1
    with run.record() as rec:
        assert rec.ticks().k.tolist() == [0, 1, 2, 3, 4] and rec.meta_json("extra")["end_reason"] == "duration"


def test_a_converged_end_the_recorded_truth_contradicts_is_refused_and_recording_goes_on(tmp_path: Path) -> None:
    run = started(tmp_path)
    run.tick(0, 0.0)
    run.step(0.1, clock(1, end=True, reason="converged", source="forger-zid"), truth(1), world(False))
    (refused,) = run.refused
    assert refused.source == "forger-zid" and "not converged" in refused.why and run.exit is None
    run.tick(2, 0.2)
    run.stop(0.3)
    with run.record() as rec:
        assert rec.ticks().k.tolist() == [0, 1, 2] and "end_reason" not in rec.meta_json("extra")


def test_a_stop_with_the_end_recorded_in_the_same_step_is_a_recorded_end(tmp_path: Path) -> None:
    run = started(tmp_path)
    run.tick(0, 0.0)
    run.step(0.1, clock(1, end=True, reason="duration"), truth(1), world(False), Stop())
    assert run.exit is not None and run.exit.reason == "recorded"
    with run.record() as rec:
        assert rec.meta["finished"] == "1" and rec.meta_json("extra")["end_reason"] == "duration"


def test_a_world_stopped_by_its_signal_is_not_a_finished_mission(tmp_path: Path) -> None:
    run = started(tmp_path)
    run.tick(0, 0.0)
    run.step(0.1, clock(1, end=True, reason="stopped"), truth(1), world(False))
    assert run.exit is not None and run.exit.reason == "recorded"
    with run.record() as rec:
        assert rec.meta["finished"] == "0" and rec.meta_json("extra")["end_reason"] == "stopped"


def test_a_monitor_stopped_before_any_clock_closes_a_record_with_no_wall_time(tmp_path: Path) -> None:
    run = started(tmp_path)
    run.stop(5.0)
    with run.record() as rec:
        assert rec.ticks().k.tolist() == [] and rec.meta["finished"] == "0"
        assert "wall_time_s" not in rec.meta  # (the mission never started)


# ------------------------------------------------------------------------------------------ determinism


def test_determinism_is_lost_at_the_earliest_conflicting_command_reported(tmp_path: Path) -> None:
    run = started(tmp_path)
    for k in range(6):
        run.tick(k, 0.01 * k)
    run.step(0.06, world_report((("conflicting_command", "stranger", 1, 3 * DT),)))
    run.step(0.07, world_report((("conflicting_command", "stranger", 2, 1 * DT),)))
    run.step(0.08, world_report((("conflicting_command", "stranger", 3, 4 * DT),)))
    run.stop(0.1)
    with run.record() as rec:
        s = summarize(rec)
    assert (s["deterministic"], s["determinism_lost_at_s"]) == (False, DT)


def test_an_agent_guessing_at_tick_0_loses_determinism_at_t_0(tmp_path: Path) -> None:
    run = started(tmp_path)
    for k in range(3):  # agent IDS[1] guessed at tick 0, agent IDS[2] at tick 2 (later: not the first)
        guessed = {IDS[1]: 0, IDS[2]: 2 if k == 2 else -1}
        run.step(0.01 * k, clock(k), truth(k), *(report(a, 0, guessed.get(a, -1)) for a in IDS))
    run.stop(0.1)
    with run.record() as rec:
        s = summarize(rec)
    assert (s["deterministic"], s["determinism_lost_at_s"]) == (False, 0.0)


# ------------------------------------------------------------------------------------------ who is alive


def test_after_its_router_link_is_back_an_agent_whose_token_goes_is_lost(tmp_path: Path) -> None:
    run = started(tmp_path)
    run.tick(0, 0.0)
    run.step(0.1, RouterReach(False))
    run.step(0.2, RouterReach(True))
    now = 0.2 + T.relink_settle_s + 0.5  # (tokens that go while the sessions settle are kept)
    k = 1
    t = 0.3
    while t < now:
        run.tick(k, t)
        k, t = k + 1, t + 0.5
    run.step(t, token(IDS[2], False))
    run.tick(k, t + 0.5, quiet=(IDS[2],))
    assert kinds(run.events) == [("agent_lost", IDS[2])]


def test_a_run_whose_first_clock_comes_long_after_the_tokens_loses_nobody(tmp_path: Path) -> None:
    run = Run(tmp_path)
    run.step(0.0, *tokens(True))
    for k in range(40):  # the first clock 30 s after the tokens; every agent reports from then on
        run.tick(k, 30.0 + 0.5 * k)
    assert run.events == []


# ------------------------------------------------------------------------------------------ the record


def test_ticks_missing_right_after_the_first_and_a_single_missing_tick_are_gaps(tmp_path: Path) -> None:
    run = started(tmp_path)
    for k in (0, 2, 5):
        run.tick(k, 0.01 * k)
    run.stop(0.1)
    with run.record() as rec:
        gaps = [(g["t_from"], g["t_to"], g["note"]) for g in rec.gaps()]
    assert [x for a, b, _ in gaps for x in (a, b)] == pytest.approx([0.0, 2 * DT, 2 * DT, 5 * DT])
    assert "1..1" in gaps[0][2] and "3..4" in gaps[1][2]


def test_a_truth_that_comes_twice_is_recorded_once_with_its_headings(tmp_path: Path) -> None:
    run = started(tmp_path)
    run.tick(0, 0.0)
    tr = truth(1)
    turned = replace(tr, theta=tuple(0.25 for _ in IDS))
    run.step(0.1, clock(1), turned)
    run.step(0.2, turned)
    run.stop(0.3)
    with run.record() as rec:
        ticks = rec.ticks()
        assert ticks.k.tolist() == [0, 1] and ticks.theta[1].tolist() == [0.25] * len(IDS)
        assert run.node.min_gap == pytest.approx(min(ticks.min_agent_gap_m.tolist()))


def test_what_the_world_and_the_monitor_dropped_are_counted_each(tmp_path: Path) -> None:
    run = started(tmp_path)
    c = clock(0).clock
    run.step(0.0, ClockFrom(type(c)(c.k, c.t, c.alive, c.mode, rejected=5), "world-zid"), truth(0))
    run.step(0.1, truth(1, ids=[999, *IDS[1:]]), truth(2, ids=[998, *IDS[1:]]))
    run.stop(0.2)
    with run.record() as rec:
        counters = rec.counters()
    assert (counters["simworld"], counters["monitor"]) == (5, 2)


def test_an_end_whose_tick_is_recorded_stands_only_once_the_world_is_gone(tmp_path: Path) -> None:
    """A forger's end at tick 1 comes with tick 1's truth: recorded, but the world is still there (its token
    even declared again), so the monitor waits, and the world's next clock refutes the end."""
    run = started(tmp_path)
    run.tick(0, 0.0)
    run.step(0.1, clock(1, end=True, reason="duration", source="forger-zid"), truth(1))
    assert run.exit is None
    run.step(0.2, world(True))
    assert run.exit is None
    run.tick(2, 0.3)
    assert run.exit is None and [r.source for r in run.refused] == ["forger-zid"]


# ------------------------------------------------------------------------------------------ a restarted monitor


def restarted(tmp_path: Path, last_k: int) -> Run:
    """A record holding ticks 0..last_k, and a second monitor appending to it (every agent's token there)."""
    first = started(tmp_path)
    for k in range(last_k + 1):
        first.tick(k, 0.01 * k)
    first.stop(1.0)
    again = Run(tmp_path, offset=1005.0, append=True)
    assert again.step(0.0, *tokens(True)) == []
    return again


def test_a_restarted_monitor_takes_no_truth_of_the_ticks_it_has_and_notes_one_gap(tmp_path: Path) -> None:
    """The world's publisher sends the record's last tick (2) again: not recorded again; the restart's gap is one,
    from tick 2 to the first new tick (40)."""
    run = restarted(tmp_path, 2)
    run.step(0.05, truth(2))
    run.tick(40, 0.1)
    run.stop(0.2)
    with run.record() as rec:
        assert rec.ticks().k.tolist() == [0, 1, 2, 40]
        assert [(g["t_from"], g["t_to"]) for g in rec.gaps()] == [(pytest.approx(2 * DT), pytest.approx(40 * DT))]


def test_a_restarted_monitor_sees_no_split_across_its_gap_and_one_right_after_it(tmp_path: Path) -> None:
    """The swarm in one line after the restart, 10 m apart (one group): no split or merge across the gap. Agent 1
    goes 10 km away at tick 50, 0.5 s after the restart's first tick, and stays: one split at tick 50's time,
    confirmed once it persisted (1 s)."""
    run = restarted(tmp_path, 2)
    line = np.column_stack([10.0 * np.arange(len(IDS)), np.zeros(len(IDS))])
    far = line.copy()
    far[0] = (10_000.0, 0.0)
    for k in range(40, 50):
        run.tick(k, 0.01 * k, p=line)
    assert [e for e in run.events if e.kind in (EventKind.SPLIT, EventKind.MERGE)] == []
    for k in range(50, 81):
        run.tick(k, 0.01 * k, p=far)
    run.stop(2.0)
    (split,) = [e for e in run.events if e.kind in (EventKind.SPLIT, EventKind.MERGE)]
    assert split.kind == EventKind.SPLIT and split.t == pytest.approx(50 * DT) and (IDS[0],) in split.after


def test_a_restarted_monitor_stamps_a_loss_before_its_first_clock_with_the_records_time(tmp_path: Path) -> None:
    """The record stands at tick 40 (t = 2 s); an agent's token goes before the second monitor's first clock: its
    loss is at t = 2 s, the record's time, not 0."""
    run = restarted(tmp_path, 40)
    run.step(0.1, token(IDS[2], False))
    (lost,) = run.step(0.5)
    assert (lost.kind, lost.agent, lost.t) == (EventKind.AGENT_LOST, IDS[2], pytest.approx(40 * DT))


def test_an_agent_never_heard_gets_its_grace_from_the_first_clock_not_from_the_tokens(tmp_path: Path) -> None:
    """Tokens at 0 s, the first clock at 30 s, then 6.45 s of simulated time within 1.3 s of wall; agent 4 never
    reports: it is not lost within grace_s (10 s) of wall time from the first clock, and lost after it."""
    run = Run(tmp_path)
    run.step(0.0, *tokens(True))
    quiet = (IDS[3],)
    for k in range(130):
        run.tick(k, 30.0 + 0.01 * k, quiet=quiet)
    assert run.events == []
    run.tick(130, 40.5, quiet=quiet)
    assert kinds(run.events) == [("agent_lost", IDS[3])]
