"""The monitor's node (monitor/node.py) against its state machine, driven by hand (tests/unit/monitor_run.py):
no zenoh, no processes, times given; its rows go to a real run.db in a temporary directory."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from monitor.rows import Commit, Counters, Meta
from reconswarm.net.node import Invalid, RouterReach
from reconswarm.net.wire import wire
from reconswarm.paper.events import MEMBERSHIP, EventKind
from reconswarm.record.summary import summarize
from tests.unit.monitor_run import (
    DT,
    IDS,
    Run,
    S,
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


def test_a_single_loss_and_return_are_membership_events_only(tmp_path: Path) -> None:
    run = started(tmp_path)
    run.tick(0, 0.0)
    run.step(0.5, token(IDS[4], False))  # its token goes: gone once confirmed (token_confirm_s)
    assert run.events == []
    (lost,) = run.tick(1, 0.9, quiet=(IDS[4],))
    assert (lost.kind, lost.agent, lost.t, lost.wall_unix) == (EventKind.AGENT_LOST, IDS[4], DT, 1000.9)
    assert IDS[4] in lost.before[0] and IDS[4] not in lost.after[0]
    run.step(1.0, token(IDS[4], True))
    run.tick(2, 2.0)
    run.tick(3, 2.6)  # the burst is over: one loss is no split
    assert kinds(run.events) == [("agent_lost", IDS[4]), ("agent_joined", IDS[4])]
    run.stop(3.0)
    with run.record() as rec:
        assert rec.events() == [e.to_dict() for e in run.events]  # the record and the wire: the same events


def test_an_agent_is_alive_by_its_token_and_its_own_reports(tmp_path: Path) -> None:
    run = started(tmp_path)
    silent, untokened = IDS[2], IDS[6]
    for k in range(70):  # realtime pace: 1 s of simulated time a wall second
        quiet = (silent,) if 10 < k < 60 else ()  # its token stays, its reports stop for a while
        run.tick(k, k * DT, quiet=quiet)
        if k == 20:
            run.step(k * DT, token(untokened, False))  # its token goes, its reports go on
    lost_untokened, lost_silent, back = [e for e in run.events if e.kind in MEMBERSHIP]
    # A token that went is gone (once confirmed) whatever its reports say.
    assert (lost_untokened.kind, lost_untokened.agent) == (EventKind.AGENT_LOST, untokened)
    assert lost_untokened.t == pytest.approx(26 * DT)  # token_confirm_s after it went
    # Silent: gone once neither 2 s of wall time nor 2 s of simulated time brought a report (last at tick 10).
    assert (lost_silent.kind, lost_silent.agent, lost_silent.t) == (EventKind.AGENT_LOST, silent, round(51 * DT, 9))
    assert (back.kind, back.agent, back.t) == (EventKind.AGENT_JOINED, silent, round(60 * DT, 9))  # it reports again


def test_our_own_router_link_going_is_nobodys_loss(tmp_path: Path) -> None:
    def outage(link: bool) -> list[tuple[str, int | None]]:
        run = started(tmp_path / str(link))
        run.tick(0, 0.0)
        run.step(1.0, *([RouterReach(False)] if link else []), *tokens(False))  # every token goes at once
        run.step(1.5, *([RouterReach(True)] if link else []))
        run.step(1.6, *tokens(True))  # and they come back through the new router
        for k in range(1, 4):
            run.tick(k, 2.0 + k)
        return kinds(run.events)

    assert outage(link=True) == []
    assert outage(link=False) == [("agent_lost", a) for a in IDS] + [("agent_joined", a) for a in IDS]


def test_several_lost_together_is_a_network_split_then_a_merge(tmp_path: Path) -> None:
    run = started(tmp_path)
    run.tick(0, 0.0)
    gone = IDS[:3]
    for j, a in enumerate(gone):
        run.step(0.1 + 0.2 * j, token(a, False))
    run.tick(1, 0.9, quiet=tuple(gone))
    assert [e.kind for e in run.events] == [EventKind.AGENT_LOST] * 3  # the burst is still open
    (split,) = run.tick(2, 1.6, quiet=tuple(gone))
    rest = sorted(set(IDS) - set(gone))
    assert split.kind == EventKind.SPLIT and split.cause == "network" and split.t == 0.0
    assert split.before == (tuple(IDS),) and set(split.after) == {tuple(rest), tuple(sorted(gone))}
    for k in range(3, 6):
        assert run.tick(k, k - 0.4, quiet=tuple(gone)) == []
    assert kinds(run.step(5.0, *tokens(True, gone))) == [("agent_joined", a) for a in gone]
    assert run.tick(6, 5.5) == []
    (merge,) = run.tick(7, 6.1)
    assert merge.kind == EventKind.MERGE and merge.after == (tuple(IDS),) and merge.t == pytest.approx(5 * DT)
    assert set(merge.before) == {tuple(rest), tuple(sorted(gone))}


def test_a_world_stall_is_one_event_and_flapping_tokens_are_not_losses(tmp_path: Path) -> None:
    run = started(tmp_path)
    for k in range(3):
        run.tick(k, 0.01 * k)
    run.step(1.0)
    assert run.node.stall_since is None
    run.step(2.5)  # no clock for 2.5 s: the world stalls
    assert run.node.stall_since == pytest.approx(0.02)
    run.step(6.0, *tokens(False))  # every agent reconnects meanwhile (a new session: token off, then on)
    run.step(6.1, *tokens(True))
    run.step(7.0, token(IDS[7], False))  # and one dies for real
    run.step(7.5)
    run.step(8.0, world(False))
    assert run.events == []
    (stall,) = run.step(10.0, clock(3), truth(3), *(report(a) for a in IDS if a != IDS[7]))
    assert stall.kind == EventKind.WORLD_STALLED and stall.duration_s == pytest.approx(9.98)
    assert stall.t == pytest.approx(2 * DT)
    assert run.step(10.5) == []  # judged burst_s after the world is back
    assert kinds(run.step(11.1)) == [("agent_lost", IDS[7])]


def test_a_world_that_never_comes_back_is_lost_not_the_agents(tmp_path: Path) -> None:
    run = started(tmp_path)
    run.tick(0, 0.0)
    run.step(0.3, world(False))
    run.step(5.0, *tokens(False))
    run.step(6.0)
    (lost,) = run.stop(20.0)
    assert lost.kind == EventKind.WORLD_LOST and lost.duration_s == pytest.approx(20.0)
    assert run.exit is not None and run.exit.reason == "stopped"
    with run.record() as rec:
        assert rec.meta_json("extra")["end_reason"] == "world lost" and rec.meta["finished"] == "0"
        assert [e["kind"] for e in rec.events()] == ["world_lost"]


def test_ticks_never_received_are_a_gap(tmp_path: Path) -> None:
    run = started(tmp_path)
    for k in (0, 1, 5, 6):
        run.tick(k, 0.01 * k)
    run.step(0.1, truth(3))  # too late: already past
    run.stop(0.2)
    with run.record() as rec:
        assert rec.ticks().k.tolist() == [0, 1, 5, 6]
        (gap,) = rec.gaps()
        assert gap["t_from"] == pytest.approx(DT) and gap["t_to"] == pytest.approx(5 * DT)
        assert "2..4" in gap["note"]


def test_the_record_is_committed_every_commit_sim_s_and_counted_every_commit_wall_s(tmp_path: Path) -> None:
    run = started(tmp_path)
    for k in range(25):
        run.tick(k, 0.1 * k)
    assert [r.t_s for r in run.rows if isinstance(r, Commit)] == pytest.approx([0.5, 1.0])
    counted = [r for r in run.rows if isinstance(r, Counters)]
    assert len(counted) == 5  # at 0.0 (the first step), then whenever more than 0.5 s passed: 0.6, 1.2, 1.8, 2.4
    assert [r for r in run.rows if isinstance(r, Meta)] == [Meta((("mode", "lockstep"),)),
                                                            Meta((("mission_start_unix", "1000.000000"),))]


Guesses = tuple[tuple[int, int], ...]  # (agent, the first tick it acted on without all its data)


@pytest.mark.parametrize("guesses", [(), ((IDS[2], 7), (IDS[1], 4), (IDS[2], 7))])
def test_the_summary_says_whether_lockstep_stayed_deterministic(tmp_path: Path, guesses: Guesses) -> None:
    run = started(tmp_path)
    for k in range(10):  # each agent reports the first tick it acted on without all its data (-1: none)
        g = {a: min((gk for ga, gk in guesses if ga == a and gk <= k), default=-1) for a in IDS}
        run.step(0.01 * k, clock(k), truth(k), *(report(a, 0, g[a]) for a in IDS))
    run.stop(0.2)
    with run.record() as rec:
        s = summarize(rec)
    assert s["mode"] == "lockstep"
    assert (s["deterministic"], s["determinism_lost_at_s"]) == ((True, None) if not guesses else (False, 4 * DT))


def test_topology_events_are_recorded_and_published_alike(tmp_path: Path) -> None:
    run = started(tmp_path)
    far = S.starts.copy()
    far[: len(IDS) // 2] += (0.0, 500.0)  # half the swarm far away: the graph splits
    k = 0
    for k in range(60):
        run.tick(k, 0.01 * k, far if k >= 5 else None)
    run.step(0.7, Invalid("swarm/x/clock", "not msgpack"), Invalid("swarm/x/truth", "truncated"))
    run.step(1.0, clock(k + 1, end=True, reason="duration"), truth(k + 1, far), world(False))  # (not converged)
    assert run.exit is not None and run.exit.reason == "recorded"  # the world closed its session after its end
    out = run.events
    assert out and all(e.kind == EventKind.SPLIT and e.t_confirmed is not None for e in out)
    assert all(e.t == pytest.approx(5 * DT) for e in out)  # when the change began, confirmed later
    with run.record() as rec:
        assert rec.events() == [e.to_dict() for e in out]
        assert rec.meta_json("extra")["end_reason"] == "duration" and rec.counters()["monitor"] == 2
        assert float(rec.meta["wall_time_s"]) == pytest.approx(1.0)  # from the first clock
    assert wire.event_from_wire(wire.event_to_wire(out[0])) == out[0]


def test_the_end_waits_for_the_last_tick_or_the_grace(tmp_path: Path) -> None:
    run = started(tmp_path)
    run.tick(0, 0.0)
    run.step(0.1, clock(2, end=True, reason="duration"))
    run.step(0.2, token(IDS[0], False))  # agents leave at the end: not a loss
    run.step(3.0)
    assert run.exit is None  # tick 2 not in yet, the world not gone, the grace not over
    run.step(3.2)
    assert run.exit is not None and run.events == []
    with run.record() as rec:
        assert rec.meta_json("extra")["end_reason"] == "duration" and rec.meta["finished"] == "1"


def test_what_names_no_agent_of_the_run_is_counted_not_believed(tmp_path: Path) -> None:
    run = started(tmp_path)
    run.tick(0, 0.0)
    run.step(0.1, truth(1, ids=[999, *IDS[1:]]), report(999, 7), Invalid("swarm/x/report/agent-1", "bad"),
             token(999, True), report(IDS[0], 4))
    run.stop(0.2)
    with run.record() as rec:
        assert rec.ticks().k.tolist() == [0]
        counters = rec.counters()
    assert counters["monitor"] == 3 and counters[f"agent {IDS[0]}"] == 4 and "agent 999" not in counters


def test_a_stop_records_what_came_with_it_and_refuses_an_end_the_truth_does_not_back(tmp_path: Path) -> None:
    run = started(tmp_path)
    run.tick(0, 0.0)
    run.step(0.1, clock(5, end=True))  # "converged", its tick not in yet
    run.stop(0.2, truth(1))  # the tick that came with the signal is recorded first
    assert run.exit is not None and run.exit.reason == "stopped"
    (refused,) = run.refused
    assert refused.source == "world-zid" and "not converged" in refused.why
    with run.record() as rec:
        assert rec.ticks().k.tolist() == [0, 1] and rec.meta["finished"] == "0"
        assert "end_reason" not in rec.meta_json("extra")


def test_a_world_report_with_a_conflicting_command_is_recorded_and_ends_determinism(tmp_path: Path) -> None:
    run = started(tmp_path)
    for k in range(4):
        run.tick(k, 0.01 * k)
    run.step(0.05, world_report((("conflicting_command", "stranger", 2, 2 * DT),)))
    run.stop(0.1)
    with run.record() as rec:
        s = summarize(rec)
        (row,) = rec.intrusions()
    assert (s["deterministic"], s["determinism_lost_at_s"]) == (False, round(2 * DT, 9))
    assert (row["process"], row["kind"], row["source"], row["count"]) == ("simworld", "conflicting_command",
                                                                           "stranger", 2)


def test_a_restarted_monitor_appends_notes_its_gap_and_keeps_the_missions_start(tmp_path: Path) -> None:
    first = started(tmp_path, offset=1000.0)
    first.tick(0, 0.0)
    first.stop(0.1)
    again = Run(tmp_path, offset=1005.0, append=True)
    again.step(0.0, *tokens(True))
    again.tick(40, 0.0)
    again.stop(0.1)
    with again.record() as rec:
        assert rec.ticks().k.tolist() == [0, 40] and rec.gaps()[0]["note"].startswith("monitor restarted")
        assert float(rec.meta["wall_time_s"]) == pytest.approx(5.1)  # from the first monitor's first clock
        assert rec.meta["mission_start_unix"] == "1000.000000"


def test_the_node_waits_for_nothing_and_sets_no_timer_of_its_own(tmp_path: Path) -> None:
    run = started(tmp_path)
    run.tick(0, 0.0)
    assert run.node.awaiting(0.1) is None and run.node.wake_at_s() is None  # the truth (urgent) or its poll
    assert np.array_equal(run.node.alive, np.ones(len(IDS), dtype=bool))


def test_each_step_that_records_a_tick_gives_the_live_views_its_scene_and_no_other_step_does(tmp_path: Path) -> None:
    """The live views (Foxglove, the terminal's table) take the node's `Scene` output, not its internals: the newest
    tick a step recorded, as copies (a later tick does not change a scene already given)."""
    run = started(tmp_path)
    assert run.scenes == []
    p0 = S.starts + 1.0
    run.tick(0, 0.0, p0)
    (sc,) = run.scenes
    assert (sc.k, sc.t_s) == (0, 0.0) and np.array_equal(sc.p, p0) and sc.alive.all() and sc.rejected == 0
    assert sc.n_groups >= 1 and sc.edges.shape[1] == 2 and sc.min_gap_m == pytest.approx(sc.gaps_m[0])
    run.step(0.1, report(IDS[0], rejected=3))  # no new tick: no scene
    assert len(run.scenes) == 1
    run.step(0.2, clock(1), truth(1, p0 + 2.0))
    assert [s.k for s in run.scenes] == [0, 1] and np.array_equal(run.scenes[0].p, p0)  # (the first one kept)
    assert np.array_equal(run.scenes[1].p, p0 + 2.0) and run.scenes[1].t_s == pytest.approx(DT)
    assert run.scenes[1].rejected == 3  # (what agent 1 reported it dropped)
