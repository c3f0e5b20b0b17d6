"""The monitor's logic (monitor/node.py) driven by hand: no zenoh, no processes, times given; the record
is a real run.db in a temporary directory."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from monitor.node import MonitorNode
from reconswarm.net import wire
from reconswarm.net.keys import WireError
from reconswarm.net.timing import Timing
from reconswarm.paper.events import Event, EventKind
from reconswarm.record.store import RunRecord, RunWriter
from reconswarm.record.summary import summarize
from reconswarm.scenario.model import load
from tests.support import PAPER

T = Timing(burst_s=1.0, end_grace_s=3.0, commit_sim_s=0.5, world_stall_s=2.0)
S = load(PAPER)
IDS = [a.id for a in S.agents]
DT = S.meta.dt_s


def truth(k: int, p: np.ndarray | None = None) -> wire.Truth:
    p = S.starts if p is None else p
    return wire.Truth(k, k * DT, tuple(IDS), tuple(p[:, 0]), tuple(p[:, 1]), tuple(S.headings), tuple(p[:, 0]),
                      tuple(p[:, 1]))


def clock(k: int, end: bool = False) -> wire.Clock:
    return wire.Clock(k, k * DT, tuple(IDS), wire.ClockMode.LOCKSTEP, 0.0, end, "converged" if end else "", 0,
                      {"world_overruns": 0.0} if end else {})


def node_for(tmp_path: Path, offset: float = 1000.0) -> MonitorNode:
    writer = RunWriter(tmp_path / "run.db", S, "lockstep")
    node = MonitorNode(S, writer, None, T, unix_offset_s=offset)
    for a in IDS:
        node.agent_up(a, True, 0.0)
    return node


def tick(node: MonitorNode, k: int, now: float, p: np.ndarray | None = None) -> None:
    node.clock(clock(k), now)
    node.truth(truth(k, p))
    assert node.poll(now) is False


def kinds(events: list[Event]) -> list[tuple[str, int | None]]:
    return [(e.kind.value, e.agent) for e in events]


def recorded(tmp_path: Path) -> list[dict]:
    with RunRecord(tmp_path / "run.db") as rec:
        return rec.events()


def test_a_single_loss_and_return_are_membership_events_only(tmp_path: Path) -> None:
    node = node_for(tmp_path)
    assert node.take_events() == []  # the first tokens are not joins
    tick(node, 0, 0.0)
    node.agent_up(IDS[4], False, 0.5)
    tick(node, 1, 0.6)
    node.agent_up(IDS[4], True, 0.7)
    tick(node, 2, 2.0)
    out = node.take_events()
    assert kinds(out) == [("agent_lost", IDS[4]), ("agent_joined", IDS[4])]
    lost = out[0]
    assert lost.t == 0.0 and lost.wall_unix == 1000.5 and IDS[4] in lost.before[0] and IDS[4] not in lost.after[0]
    node.finish(3.0, 0)
    assert recorded(tmp_path) == [e.to_dict() for e in out]  # the record and the wire: the same events


def test_several_lost_together_is_a_network_split_then_a_merge(tmp_path: Path) -> None:
    node = node_for(tmp_path)
    tick(node, 0, 0.0)
    gone = IDS[:3]
    for j, a in enumerate(gone):
        node.agent_up(a, False, 0.1 + 0.2 * j)
    tick(node, 1, 0.9)
    assert [e.kind for e in node.take_events()] == [EventKind.AGENT_LOST] * 3  # the burst is still open
    tick(node, 2, 1.2)
    (split,) = node.take_events()
    rest = sorted(set(IDS) - set(gone))
    assert split.kind == EventKind.SPLIT and split.cause == "network"
    assert split.before == (tuple(IDS),) and set(split.after) == {tuple(rest), tuple(sorted(gone))}
    for a in gone:
        node.agent_up(a, True, 5.0)
    tick(node, 3, 5.5)
    assert kinds(node.take_events()) == [("agent_joined", a) for a in gone]
    tick(node, 4, 6.1)
    (merge,) = node.take_events()
    assert merge.kind == EventKind.MERGE and merge.after == (tuple(IDS),) and merge.t == pytest.approx(2 * DT)
    assert set(merge.before) == {tuple(rest), tuple(sorted(gone))}


def test_a_world_stall_is_one_event_and_flapping_tokens_are_not_losses(tmp_path: Path) -> None:
    node = node_for(tmp_path)
    for k in range(3):
        tick(node, k, 0.01 * k)
    node.take_events()
    assert node.poll(1.0) is False and node.stall_since is None
    node.poll(2.5)  # no clock for 2.5 s: the world stalls
    assert node.stall_since == pytest.approx(0.02)
    for a in IDS:  # every agent reconnects meanwhile (a new session: token off, then on)
        node.agent_up(a, False, 6.0)
        node.agent_up(a, True, 6.1)
    node.agent_up(IDS[7], False, 7.0)  # and one dies for real
    node.world_up(False, 8.0)
    assert node.take_events() == []
    node.clock(clock(3), 10.0)
    node.truth(truth(3))
    node.poll(10.0)
    (stall,) = node.take_events()
    assert stall.kind == EventKind.WORLD_STALLED and stall.duration_s == pytest.approx(9.98)
    assert stall.t == pytest.approx(2 * DT)
    node.poll(10.5)
    assert node.take_events() == []  # judged burst_s after the world is back
    node.poll(11.1)
    assert kinds(node.take_events()) == [("agent_lost", IDS[7])]


def test_a_world_that_never_comes_back_is_lost_not_the_agents(tmp_path: Path) -> None:
    node = node_for(tmp_path)
    tick(node, 0, 0.0)
    node.world_up(False, 0.3)
    for a in IDS:
        node.agent_up(a, False, 5.0)
    node.poll(6.0)
    node.finish(20.0, 0)
    (lost,) = node.take_events()
    assert lost.kind == EventKind.WORLD_LOST and lost.duration_s == pytest.approx(20.0)
    with RunRecord(tmp_path / "run.db") as rec:
        assert rec.meta_json("extra")["end_reason"] == "world lost" and rec.meta["finished"] == "0"
        assert [e["kind"] for e in rec.events()] == ["world_lost"]


def test_ticks_never_received_are_a_gap(tmp_path: Path) -> None:
    node = node_for(tmp_path)
    for k in (0, 1, 5, 6):
        tick(node, k, 0.01 * k)
    node.truth(truth(3))  # too late: already past
    node.poll(0.1)
    node.finish(0.2, 0)
    with RunRecord(tmp_path / "run.db") as rec:
        assert rec.ticks().k.tolist() == [0, 1, 5, 6]
        (gap,) = rec.gaps()
        assert gap["t_from"] == pytest.approx(DT) and gap["t_to"] == pytest.approx(5 * DT)
        assert "2..4" in gap["note"]


Guesses = tuple[tuple[int, int], ...]  # (agent, the first tick it acted on without all its data)


@pytest.mark.parametrize("guesses", [(), ((IDS[2], 7), (IDS[1], 4), (IDS[2], 7))])
def test_the_summary_says_whether_lockstep_stayed_deterministic(tmp_path: Path, guesses: Guesses) -> None:
    node = node_for(tmp_path)
    for k in range(10):
        tick(node, k, 0.01 * k)
        for a in IDS:  # each agent reports the first tick it acted on without all its data (-1: none)
            g = min((gk for ga, gk in guesses if ga == a and gk <= k), default=-1)
            node.telemetry(a, 0, g)
    node.finish(0.2, 0)
    with RunRecord(tmp_path / "run.db") as rec:
        s = summarize(rec)
    assert s["mode"] == "lockstep"
    assert (s["deterministic"], s["determinism_lost_at_s"]) == ((True, None) if not guesses else (False, 4 * DT))


def test_topology_events_are_recorded_and_published_alike(tmp_path: Path) -> None:
    node = node_for(tmp_path)
    far = S.starts.copy()
    far[: len(IDS) // 2] += (0.0, 500.0)  # half the swarm far away: the graph splits
    k = 0
    for k in range(60):
        tick(node, k, 0.01 * k, far if k >= 5 else None)
    end = clock(k + 1, end=True)
    node.clock(wire.Clock(end.k, end.t, end.alive, end.mode, end.speed, True, "duration"), 1.0)  # (not converged)
    node.truth(truth(k + 1, far))
    node.world_up(False, 1.0)  # the world closes its session after its end
    assert node.poll(1.0) is True
    node.finish(1.1, 2)
    out = node.take_events()
    assert out and all(e.kind == EventKind.SPLIT and e.t_confirmed is not None for e in out)
    assert all(e.t == pytest.approx(5 * DT) for e in out)  # when the change began, confirmed later
    assert recorded(tmp_path) == [e.to_dict() for e in out]
    assert wire.event_from_wire(wire.event_to_wire(out[0])) == out[0]
    with RunRecord(tmp_path / "run.db") as rec:
        assert rec.meta_json("extra")["end_reason"] == "duration" and rec.counters()["monitor"] == 2
        assert float(rec.meta["wall_time_s"]) == pytest.approx(1.1)  # from the first clock


def test_the_end_waits_for_the_last_tick_or_the_grace(tmp_path: Path) -> None:
    node = node_for(tmp_path)
    tick(node, 0, 0.0)
    node.clock(wire.Clock(2, 2 * DT, tuple(IDS), wire.ClockMode.LOCKSTEP, 0.0, True, "duration"), 0.1)
    assert node.poll(0.1) is False  # tick 2 not in yet
    node.agent_up(IDS[0], False, 0.2)  # agents leave at the end: not a loss
    assert node.poll(3.2) is True and node.take_events() == []


def test_bad_input_is_refused(tmp_path: Path) -> None:
    node = node_for(tmp_path)
    bad = wire.Truth(0, 0.0, (999,), (0.0,), (0.0,), (0.0,), (0.0,), (0.0,))
    with pytest.raises(WireError):
        node.truth(bad)
    with pytest.raises(WireError):
        node.telemetry(999, 0, -1)
    node.telemetry(IDS[0], 4, -1)
    tick(node, 0, 0.0)
    assert node.counts[f"agent {IDS[0]}"] == 4


def test_a_restarted_monitor_notes_its_gap(tmp_path: Path) -> None:
    node = node_for(tmp_path)
    tick(node, 0, 0.0)
    node.finish(0.1, 0)
    writer = RunWriter(tmp_path / "run.db", S, "lockstep", append=True)
    again = MonitorNode(S, writer, writer.last_tick(), T)
    tick(again, 40, 0.0)
    again.finish(0.1, 0)
    with RunRecord(tmp_path / "run.db") as rec:
        assert rec.ticks().k.tolist() == [0, 40] and rec.gaps()[0]["note"].startswith("monitor restarted")
