"""The agent's protocol logic (agent/node.py) driven by hand: decoded messages and a fake clock, no processes.

Each command the node sends is compared with what the real AgentBrain computes from the inputs the
protocol says it must use (its state at k, every peer's latest announcement, the linked peers' sets).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest

from agent.brain import AgentBrain, Peer
from agent.messages import Output, Reconnect
from agent.neighbours import Cells
from reconswarm.net.node import Exit, Invalid, Stop
from reconswarm.net.timing import Timing
from reconswarm.net.wire import wire
from reconswarm.scenario.model import PlannerKind, Scenario, load
from tests.support import PAPER, joined, left, world_token
from tests.unit.solo import SoloNode

A, B, C = 1, 2, 3  # the node under test and two peers
HEAD = {A: (100.0, 0.0), B: (110.0, 0.0), C: (120.0, 0.0)}  # where their head points start (tick 0)
S = dataclasses.replace(load(PAPER), agents=tuple(  # (in the paper's scenario, moved there: heading 0, l = 0.5)
    dataclasses.replace(a, start_m=(HEAD[a.id][0] - 0.5, HEAD[a.id][1])) if a.id in HEAD else a
    for a in load(PAPER).agents))
DT = S.meta.dt_s
# The world is taken to speak throughout: these tests jump over seconds without its clock published again every
# republish_s, which the node would take for a stalled world (its own tests: tests/unit/test_agent_node_waits.py).
T = Timing(world_quiet_s=math.inf)
RADIUS = {a.id: a.radius_m for a in S.agents}


def state(k: int, px: float, py: float, aid: int = A, scan: wire.Scan | None = None) -> wire.State:
    return wire.State(aid, k, k * DT, px, py, 0.0, px, py, scan)


def clock(k: int, alive: tuple[int, ...] = (A, B, C), **kw: object) -> wire.Clock:
    return wire.Clock(k, k * DT, alive, **kw)  # type: ignore[arg-type]


def beacon(aid: int, k: int, px: float, py: float, rev: int = 0) -> wire.Beacon:
    return wire.Beacon(aid, k, k * DT, px, py, RADIUS[aid], rev)


def no_cells(out: list[Output]) -> list[Output]:
    """What goes on the wire (the cells to listen to are the host's business: tests/unit/test_neighbours.py)."""
    return [o for o in out if not isinstance(o, Cells)]


def cmds(out: list[Output]) -> list[wire.Cmd]:
    return [o for o in out if isinstance(o, wire.Cmd)]


def beacons(out: list[Output]) -> list[wire.Beacon]:
    return [o for o in out if isinstance(o, wire.Beacon)]


def reference(k: int, p: tuple[float, float], peers: list[Peer], brain: AgentBrain | None = None,
              scan: dict[str, np.ndarray] | None = None, shared: list[dict[str, np.ndarray]] | None = None,
              s: Scenario = S) -> tuple[float, float]:
    """The command the node must send: the brain's u as (v, ω) at the state's heading (0 in these tests)."""
    brain = brain or AgentBrain(s, A)
    u, _ = brain.tick(k, np.array(p), scan or {}, peers, shared or [])
    return brain.inputs(u, 0.0)


def started(node_s: Scenario = S, peers: tuple[int, ...] = (B, C), timing: Timing = T) -> SoloNode:
    node = SoloNode(node_s, A, 0.0, timing)
    node.step([joined(A), *(joined(p) for p in peers)], 0.0)
    return node


# --------------------------------------------------------------------------------------------- lockstep

def test_lockstep_waits_for_every_live_peer_then_acts_once() -> None:
    node = started()
    assert node.awaiting(0.0) is None  # before our state nothing can let us act: the runtime sleeps on it
    out = node.step([clock(0), state(0, 100.0, 0.0)], 0.01)
    assert beacons(out) == [wire.Beacon(A, 0, 0.0, 100.0, 0.0, RADIUS[A], 0)] and not cmds(out)
    assert node.awaiting(0.01) == 2  # the beacons of B and C: the runtime wakes once both could be in
    assert not cmds(node.step([beacon(B, 0, 200.0, 0.0)], 0.02))  # C is still missing
    assert node.awaiting(0.02) == 1
    assert "beacons of [3]" in node.waiting_for()
    out = node.step([beacon(C, 0, 300.0, 0.0)], 0.03)
    want = reference(0, (100.0, 0.0), [Peer(B, 200.0, 0.0, RADIUS[B]), Peer(C, 300.0, 0.0, RADIUS[C])])
    assert [(c.k, c.v_mps, c.omega_radps) for c in cmds(out)] == [(0, *want)]
    assert node.step([], 0.04) == []  # nothing new: no second command, no second beacon


def test_lockstep_plans_with_the_scan_its_state_carries() -> None:
    node = started(peers=())
    pts = ((130.0, 0.0, "diamond"), (131.0, 1.0, "diamond"))
    out = node.step([clock(0, (A,)), state(0, 100.0, 0.0, scan=wire.Scan(A, 0, 0.0, pts))], 0.0)
    assert beacons(out)  # one message, one step: beacon, then the command planned with the scan
    scan = {"diamond": np.array([[130.0, 0.0], [131.0, 1.0]])}
    assert [(c.v_mps, c.omega_radps) for c in cmds(out)] == [reference(0, (100.0, 0.0), [], scan=scan)]
    grew = no_cells(out)[-2]
    assert isinstance(grew, wire.ObstacleSet) and grew.rev == 1  # its knowledge grew: announced
    assert node.brain.rev == 1


def test_lockstep_goes_on_without_a_lost_clock_after_the_wait_timeout() -> None:
    node = started(peers=())
    node.step([clock(0, (A,)), state(0, 100.0, 0.0)], 0.0)
    assert node.k == 0
    out = node.step([state(1, 100.1, 0.0)], 0.1)  # clock 1 lost
    assert beacons(out) and not cmds(out)
    assert "clock" in node.waiting_for()
    out = node.step([], 0.1 + T.agent_wait_timeout_s + 0.01)
    assert [c.k for c in cmds(out)] == [1]
    assert node.guessed_k == 1  # without its clock: said (in the agent's reports), from tick 1 on
    node.step([state(2, 100.2, 0.0), clock(2, (A,))], 2 * T.agent_wait_timeout_s)
    assert node.k == 2 and node.guessed_k == 1  # the first guess stays the one said


def test_a_late_peer_is_waited_for_and_the_node_acts_when_it_arrives() -> None:
    node = started(peers=(B,))
    node.step([clock(0, (A, B)), state(0, 100.0, 0.0)], 0.0)
    assert not cmds(node.step([], 0.9 * T.agent_wait_timeout_s))
    out = node.step([beacon(B, 0, 110.0, 0.0)], 0.95 * T.agent_wait_timeout_s)
    want = reference(0, (100.0, 0.0), [Peer(B, 110.0, 0.0, RADIUS[B])])
    assert [(c.v_mps, c.omega_radps) for c in cmds(out)] == [want]
    assert node.guessed_k == -1  # late, but complete: no guess


def test_a_peer_the_clock_counts_is_waited_for_though_its_token_comes_later() -> None:
    """zenoh-python runs each subscriber's callbacks on a thread of their own: a peer's token may reach us after
    the world's clock that counted it (seen in CI: agent 9 acted on tick 0 before agent 4's token was in, then
    got its beacon within reach). The world saw the token: tick 0 waits for B's beacon all the same."""
    node = started(peers=(C,))  # B's token is not in yet
    out = node.step([clock(0), state(0, 100.0, 0.0), beacon(C, 0, 120.0, 0.0)], 0.0)
    assert not cmds(out) and node.awaiting(0.0) == 1 and "beacons of [2]" in node.waiting_for()
    out = node.step([beacon(B, 0, 110.0, 0.0)], 0.01)  # (its token still on its way)
    want = reference(0, (100.0, 0.0), [Peer(B, 110.0, 0.0, RADIUS[B]), Peer(C, 120.0, 0.0, RADIUS[C])])
    assert [(c.k, c.v_mps, c.omega_radps) for c in cmds(out)] == [(0, *want)]
    assert node.guessed_k == -1  # nothing was guessed: the command is the in-process engine's
    # A token we saw go (and not back within token_confirm_s) is not waited for, though the clock (of the world's
    # view a moment ago) still counts it.
    node.step([joined(B), left(B)], 0.02)
    node.step([clock(1), state(1, 100.05, 0.0), beacon(C, 1, 120.0, 0.0)], 0.05)
    assert node.k == 0  # (its token went 0.03 s ago: it may come back, as with a router that dies)
    node.step([], 0.02 + T.token_confirm_s)
    assert node.k == 1 and node.guessed_k == -1


def test_a_peer_counted_by_the_clock_but_never_heard_is_given_up_after_peer_silent_s() -> None:
    node = started(peers=(C,))
    node.step([clock(0), state(0, 100.0, 0.0), beacon(C, 0, 120.0, 0.0)], 0.0)
    assert not cmds(node.step([], T.peer_silent_s - 0.01))
    assert [c.k for c in cmds(node.step([], T.peer_silent_s + 0.01))] == [0]
    assert node.guessed_k == 0  # acted without B's beacon: said


def test_a_peer_that_never_answers_is_given_up_after_the_wait_timeout() -> None:
    node = started(peers=(B,))
    node.step([clock(0, (A, B)), state(0, 100.0, 0.0)], 0.0)
    assert not cmds(node.step([], T.agent_wait_timeout_s * 0.99))
    out = node.step([], T.agent_wait_timeout_s + 0.01)
    assert [(c.v_mps, c.omega_radps) for c in cmds(out)] == [reference(0, (100.0, 0.0), [])]
    assert node.guessed_k == 0  # acted without B's beacon: determinism lost from tick 0


def test_a_stuck_tick_announces_beacon_and_obstacle_set_again() -> None:
    node = started(peers=(B,))
    pts = ((130.0, 0.0, "diamond"), (131.0, 1.0, "diamond"), (131.0, -1.0, "diamond"))
    node.step([clock(0, (A, B)), state(0, 100.0, 0.0, scan=wire.Scan(A, 0, 0.0, pts)),
               beacon(B, 0, 140.0, 0.0)], 0.0)
    assert node.k == 0 and node.brain.rev == 1
    node.step([clock(1, (A, B)), state(1, 100.1, 0.0)], 1.0)
    # B stays silent, but was heard 1 s ago (< peer_silent_s): after beacon_again_s both go out again.
    out = node.step([], 1.0 + T.beacon_again_s + 0.01)
    assert [type(o) for o in out] == [wire.Beacon, wire.ObstacleSet] and beacons(out)[0].rev == 1
    # Then backing off, the beacon alone: 2 x beacon_again_s later, not before.
    assert node.step([], 1.0 + 2.5 * T.beacon_again_s) == []
    out = node.step([], 1.0 + 3.0 * T.beacon_again_s + 0.02)
    assert [type(o) for o in out] == [wire.Beacon]


def test_a_lost_peer_is_not_waited_for_and_stays_a_static_obstacle() -> None:
    node = started(peers=(B,))
    node.step([clock(0, (A, B)), state(0, 100.0, 0.0), beacon(B, 0, 108.0, 0.0)], 0.0)
    node.step([left(B)], 0.01)  # B's token went away
    out = node.step([clock(1, (A,)), state(1, 100.05, 0.0)], 0.05)  # acts at once: B is not waited for
    ref = AgentBrain(S, A)
    reference(0, (100.0, 0.0), [Peer(B, 108.0, 0.0, RADIUS[B])], brain=ref)
    want = reference(1, (100.05, 0.0), [Peer(B, 108.0, 0.0, RADIUS[B])], brain=ref)
    assert [(c.k, c.v_mps, c.omega_radps) for c in cmds(out)] == [(1, *want)]
    assert want != reference(1, (100.05, 0.0), [])  # B's last position does push the agent away
    assert node.guessed_k == -1  # B is gone by its membership: not a guess


def test_a_repeated_tick_resends_the_same_command_without_planning_again() -> None:
    node = started(peers=())
    first = cmds(node.step([clock(0, (A,)), state(0, 100.0, 0.0)], 0.0))
    calls: list[int] = []
    tick = node.brain.tick

    def counted(k: int, *args: Any) -> Any:
        calls.append(k)
        return tick(k, *args)

    node.brain.tick = counted  # type: ignore[method-assign, assignment]
    again = node.step([state(0, 100.0, 0.0)], 0.5)  # the world re-publishes tick 0: it missed our command
    assert again == first and calls == []


def test_a_silent_peer_alive_by_its_token_is_not_waited_for() -> None:
    node = started(peers=(B,))
    node.step([clock(0, (A, B)), state(0, 100.0, 0.0), beacon(B, 0, 140.0, 0.0)], 0.0)
    node.step([clock(1, (A, B)), state(1, 100.05, 0.0)], T.peer_silent_s + 0.1)
    assert node.k == 1  # B's last beacon is older than peer_silent_s
    assert node.guessed_k == 1  # alive by its token, yet acted on without it: said


def test_after_a_world_stall_a_peer_is_silent_only_counting_from_the_worlds_return() -> None:
    """Nobody has a state to announce while the world is frozen: B's beacon 10 s ago is not silence."""
    node = started(peers=(B,))
    node.step([clock(0, (A, B)), state(0, 100.0, 0.0), beacon(B, 0, 140.0, 0.0)], 0.0)
    node.step([world_token(False)], 2.0)
    node.step([world_token(True), clock(1, (A, B)), state(1, 100.05, 0.0)], 10.0)
    assert node.k == 0 and node.awaiting(10.0) == 1  # B's beacon for tick 1 is waited for
    node.step([], 10.0 + T.peer_silent_s - 0.01)
    assert node.k == 0
    node.step([beacon(B, 1, 140.0, 0.0)], 11.0)
    assert node.k == 1 and node.guessed_k == -1  # deterministic

def test_pruning_keeps_only_recent_ticks_and_the_merged_revision() -> None:
    node = started(peers=(B,))
    sets = {r: wire.ObstacleSet(B, r, r, {"diamond": ((130.0 + r, 0.0), (131.0, 1.0), (131.0, -1.0))})
            for r in (1, 2)}
    for k in range(22):
        rev = 1 if k < 10 else 2
        batch: list = [clock(k, (A, B)), state(k, 100.0, 0.0), beacon(B, k, 105.0, 0.0, rev)]
        if k in (0, 10):
            batch.append(sets[rev])
        assert cmds(node.step(batch, k * 0.01))[0].k == k
    assert min(node.h.states) == 18 and list(node.sets[B]) == [2]


# -------------------------------------------------------------------- restart, reconnect (issue 11 path 1)

def test_after_a_new_session_a_dead_peer_is_still_an_obstacle_at_its_last_position() -> None:
    """Kill an agent, stall the world: after resubscribe_s without commanding the agent opens a new session.
    Its dead peer must still be avoided where it was last seen (issue 11: agent 10 hit dead robot 3)."""
    node = started()
    node.step([clock(0), state(0, 100.0, 0.0), beacon(B, 0, 400.0, 0.0), beacon(C, 0, 109.0, 0.0)], 0.0)
    node.step([left(C)], 0.5)  # C is killed
    node.step([clock(1, (A, B)), state(1, 100.05, 0.0), beacon(B, 1, 400.0, 0.0)], 0.6)
    assert node.k == 1
    # The world stalls: no state for resubscribe_s, so the node asks for a new session, once.
    assert node.step([], 0.6 + T.resubscribe_s - 0.01) == []
    assert node.step([], 0.6 + T.resubscribe_s + 0.01) == [Reconnect()]
    node.reconnected(0.6 + T.resubscribe_s + 0.02)
    # The new session's liveliness history names the live agents only; then the world goes on.
    now = 0.6 + T.resubscribe_s + 0.1
    out = node.step([joined(A), joined(B), clock(2, (A, B)), state(2, 100.1, 0.0), beacon(B, 2, 400.0, 0.0)], now)
    ref = AgentBrain(S, A)
    peers = [Peer(B, 400.0, 0.0, RADIUS[B]), Peer(C, 109.0, 0.0, RADIUS[C])]
    for k, px in ((0, 100.0), (1, 100.05)):
        reference(k, (px, 0.0), peers, brain=ref)
    want = reference(2, (100.1, 0.0), peers, brain=ref)
    assert [(c.k, c.v_mps, c.omega_radps) for c in cmds(out)] == [(2, *want)]
    assert want != reference(2, (100.1, 0.0), peers[:1])  # without C the command would differ


def test_a_stalled_world_is_waited_for_not_answered_with_a_new_session() -> None:
    """The world froze past its lease (its token is gone, no clock since): no new session at resubscribe_s
    (every agent reconnecting at once made the world's return refuse their commands as impersonation, and
    lost beacons of tick k); only after resubscribe_world_gone_s, in case our own session is the broken one.
    A clock, or the token back, ends the stall: resubscribe_s counts again."""
    node = started(peers=())
    node.step([clock(0, (A,)), state(0, 100.0, 0.0)], 0.0)
    assert node.k == 0
    node.step([world_token(False)], 1.0)
    assert node.step([], T.resubscribe_s + 0.5) == []
    assert node.step([], T.resubscribe_world_gone_s - 0.01) == []
    assert node.step([], T.resubscribe_world_gone_s + 0.01) == [Reconnect()]
    node.reconnected(T.resubscribe_world_gone_s + 0.02)
    # The world is back (its token): the wait for a command counts from its return, by resubscribe_s.
    assert node.step([world_token(True)], 16.0) == []  # 1 s after the new session, but the world just came back
    assert node.step([], 16.0 + T.resubscribe_s - 0.01) == []
    assert node.step([], 16.0 + T.resubscribe_s + 0.01) == [Reconnect()]
    node.reconnected(21.1)
    node.step([world_token(False), clock(1, (A,))], 22.0)  # a clock after the token went: not stalled
    assert node.world_gone is False
    assert node.step([], 22.0 + T.resubscribe_s - 0.01) == []
    assert node.step([], 22.0 + T.resubscribe_s + 0.01) == [Reconnect()]


def test_a_slow_swarm_is_waited_for_while_the_world_publishes_our_tick_again() -> None:
    """The world waits for other agents' commands (a slow host, a starved machine) and publishes its tick again
    every republish_s: each time we send our command again, and our session plainly hears the world, so no new
    session at resubscribe_s (new sessions of every host at once made a slow run of 144 collapse: tokens gone,
    commands refused as impersonation, hosts leaving). The world moves on within its step timeout, so a tick
    published again for resubscribe_world_gone_s may be lacking ours (our way to it broken): a new session then.
    Once the world falls silent, resubscribe_s counts from the last time we commanded."""
    node = started(peers=())
    first = cmds(node.step([clock(0, (A,)), state(0, 100.0, 0.0)], 0.0))
    assert [c.k for c in first] == [0]
    t = 0.0
    while t + T.republish_s < T.resubscribe_world_gone_s:  # the world waits on tick 0
        t += T.republish_s
        out = node.step([clock(0, (A,)), state(0, 100.0, 0.0)], t)
        assert out == first, t  # our command again, and nothing else
    assert t > T.resubscribe_s + 1.0
    assert node.step([clock(0, (A,)), state(0, 100.0, 0.0)], T.resubscribe_world_gone_s + 0.01) == [*first, Reconnect()]
    node.reconnected(16.0)
    node.step([clock(1, (A,)), state(1, 100.0, 0.0)], 16.5)
    assert node.k == 1
    assert node.step([], 16.5 + T.resubscribe_s - 0.01) == []  # the world silent from here: 5 s
    assert node.step([], 16.5 + T.resubscribe_s + 0.01) == [Reconnect()]


def test_a_new_session_keeps_knowledge_revision_and_escape_state() -> None:
    node = started(peers=())
    pts = ((130.0, 0.0, "diamond"), (131.0, 1.0, "diamond"), (131.0, -1.0, "diamond"))
    node.step([clock(0, (A,)), state(0, 100.0, 0.0, scan=wire.Scan(A, 0, 0.0, pts))], 0.0)
    brain, known = node.brain, dict(node.brain.obstacle_sets())
    assert node.step([], 10.0) == [Reconnect()]
    node.reconnected(10.0)
    assert node.brain is brain and node.brain.rev == 1 and node.brain.obstacle_sets() == known
    out = node.step([clock(1, (A,)), state(1, 100.05, 0.0)], 10.1)
    # First our set again (the new session's cache starts empty), then tick 1 after tick 0.
    assert isinstance(out[0], wire.ObstacleSet) and out[0].rev == 1 and set(out[0].obstacles) == {"diamond"}
    assert beacons(out)[0].rev == 1 and cmds(out)[0].k == 1


def test_a_restarted_agent_joining_late_merges_every_cached_obstacle_set() -> None:
    node = started(peers=(B,))
    far = wire.ObstacleSet(B, 300, 4, {"hexagon": ((600.0, 0.0), (601.0, 1.0), (601.0, -1.0))})
    out = node.step([far, clock(300, (A, B)), state(300, 100.0, 0.0), beacon(B, 300, 900.0, 0.0, rev=4)], 0.0)
    assert cmds(out)[0].k == 300 and "hexagon" in node.brain.obstacle_sets()  # B is far beyond link range
    grew = no_cells(out)[-2]
    assert isinstance(grew, wire.ObstacleSet) and grew.rev == 1


def test_a_late_joiner_waits_for_every_peers_cached_set_before_its_first_tick() -> None:
    """The history replies from the peers' caches can come after the world's state (seen under load: a restarted
    agent 4 acted with no set at all). The joiner waits for a set from each peer whose beacon announces one,
    far ones included, any revision (the cache holds the newest); a set never coming is the usual guess."""
    node = started(peers=(B, C))
    hull: dict[str, tuple[tuple[float, float], ...]] = {"hexagon": ((600.0, 0.0), (601.0, 1.0), (601.0, -1.0))}
    node.step([clock(300, (A, B, C)), state(300, 100.0, 0.0), beacon(B, 300, 900.0, 0.0, rev=4),
               beacon(C, 300, 120.0, 0.0)], 0.0)
    assert node.k == -1  # B announces a set (rev 4) that has not come yet; C has none (rev 0)
    node.step([wire.ObstacleSet(B, 299, 5, hull)], 0.1)  # the cache's newest, one revision on
    assert node.k == 300 and "hexagon" in node.brain.obstacle_sets() and node.guessed_k == -1


def test_the_virtual_leader_waits_for_every_set_and_merges_the_union() -> None:
    s = dataclasses.replace(S, planner=dataclasses.replace(S.planner, kind=PlannerKind.VIRTUAL_LEADER))
    node = started(node_s=s, peers=(B,))
    hull: dict[str, tuple[tuple[float, float], ...]] = {"hexagon": ((600.0, 0.0), (601.0, 1.0), (601.0, -1.0))}
    node.step([clock(0, (A, B)), state(0, 100.0, 0.0), beacon(B, 0, 900.0, 0.0)], 0.0)
    assert node.k == 0
    node.step([clock(1, (A, B)), state(1, 100.0, 0.0), beacon(B, 1, 900.0, 0.0, rev=1)], 0.01)
    assert node.k == 0 and "obstacle" not in node.waiting_for()  # B's set is awaited though B is far
    node.step([wire.ObstacleSet(B, 0, 1, hull)], 0.02)
    assert node.k == 1 and node.merged_union == {B: 1} and node.merged == {}


# -------------------------------------------------------------------------------------------- realtime

def test_realtime_acts_on_the_newest_state_when_every_beacon_is_in() -> None:
    node = started(peers=(B,))
    rt = {"mode": "realtime", "speed": 10.0}
    out = node.step([clock(4, (A, B), **rt), state(4, 99.0, 0.0), state(5, 100.0, 0.0)], 0.0)
    assert [b.k for b in beacons(out)] == [5] and not cmds(out)  # tick 4 is stale: skipped
    assert node.wake_at_s() == pytest.approx(T.realtime_act_fraction * DT / 10.0)
    out = node.step([beacon(B, 5, 110.0, 0.0)], 0.001)
    want = reference(5, (100.0, 0.0), [Peer(B, 110.0, 0.0, RADIUS[B])])
    assert [(c.k, c.v_mps, c.omega_radps) for c in cmds(out)] == [(5, *want)]
    assert node.wake_at_s() is None


def test_realtime_acts_at_the_deadline_on_whatever_it_has() -> None:
    node = started(peers=(B,))
    rt = {"mode": "realtime", "speed": 10.0}
    node.step([clock(0, (A, B), **rt), state(0, 100.0, 0.0), beacon(B, 0, 110.0, 0.0)], 0.0)
    node.step([clock(1, (A, B), **rt), state(1, 100.05, 0.0)], 0.005)
    deadline = node.wake_at_s()
    assert deadline is not None and not cmds(node.step([], deadline - 1e-4))
    out = node.step([], deadline)
    assert [c.k for c in cmds(out)] == [1]  # B's beacon of tick 0 stands in for tick 1's


def test_realtime_a_live_peer_heard_no_more_is_not_a_ghost() -> None:
    """Realtime: a live peer that left the cells we listen to is heard no more; its last beacon shows where it
    was. Silent past realtime_peer_silent_s (wall) it is neither waited for (we act as soon as the others are in)
    nor planned with (seen: stale beacons pinned an agent in place for 180 s of a ROS 2 mission)."""
    node = started(peers=(B, C))
    rt = {"mode": "realtime", "speed": 1.0}
    node.step([clock(0, (A, B, C), **rt), state(0, 100.0, 0.0), beacon(B, 0, 104.0, 0.0), beacon(C, 0, 110.0, 0.0)],
              0.0)
    k, now = 30, T.realtime_peer_silent_s + 0.5  # C has said nothing since tick 0: it left our cells
    node.step([beacon(B, k - 1, 104.0, 0.0)], now - 0.05)
    out = node.step([clock(k, (A, B, C), **rt), state(k, 100.0, 0.0), beacon(B, k, 104.0, 0.0)], now)
    want = reference(k, (100.0, 0.0), [Peer(B, 104.0, 0.0, RADIUS[B])])
    # at once (not at the deadline), without C
    assert [(c.k, c.v_mps, c.omega_radps) for c in cmds(out)] == [(k, *want)]
    assert want != reference(k, (100.0, 0.0), [Peer(B, 104.0, 0.0, RADIUS[B]), Peer(C, 110.0, 0.0, RADIUS[C])])


def test_realtime_an_overloaded_neighbour_is_still_planned_with() -> None:
    """Overloaded realtime (the world far ahead of everyone): a neighbour's latest beacon is many ticks old,
    but it was heard moments ago: it is where it was, near us, and must still push us away."""
    node = started(peers=(B,))
    rt = {"mode": "realtime", "speed": 10.0}
    node.step([clock(0, (A, B), **rt), state(0, 100.0, 0.0), beacon(B, 0, 104.0, 0.0)], 0.0)
    k = 40  # our newest state; B is 40 ticks behind, heard 0.1 s ago
    node.step([clock(k, (A, B), **rt), state(k, 100.0, 0.0)], 0.1)
    out = node.step([], node.wake_at_s() or 0.2)
    want = reference(k, (100.0, 0.0), [Peer(B, 104.0, 0.0, RADIUS[B])])
    assert [(c.k, c.v_mps, c.omega_radps) for c in cmds(out)] == [(k, *want)]
    assert want != reference(k, (100.0, 0.0), [])


# --------------------------------------------------------------------------------- the watches and input

def test_world_silence_exits_3_and_the_end_of_mission_exits_0() -> None:
    node = started(peers=())
    node.step([clock(0, (A,)), state(0, 100.0, 0.0)], 0.0)
    assert Exit(3) in node.step([], T.world_silence_s + 0.01)
    node = started(peers=())
    assert node.step([], 1000.0) == []  # before the first clock nothing is watched
    assert node.step([clock(0, (A,), end=True, reason="converged")], 1000.1) == []  # the world's end, once
    assert node.step([world_token(False)], 1000.3) == [Exit(0)]  # its token goes after it (it closed its session)


def test_an_end_the_worlds_next_clock_contradicts_is_not_the_end() -> None:
    node = started(peers=())
    node.step([clock(0, (A,)), state(0, 100.0, 0.0)], 0.0)
    assert Exit(0) not in node.step([clock(1, (A,), end=True, reason="converged")], 0.1)  # (the world's id on it)
    node.step([clock(1, (A,)), state(1, 100.0, 0.0)], 0.2)  # the world's own clock for that tick: it goes on
    assert Exit(0) not in node.step([], 0.2 + T.end_confirm_s + 1.0)
    node = started(peers=(), timing=dataclasses.replace(T, end_confirm_s=1.0))
    node.step([clock(0, (A,)), state(0, 100.0, 0.0)], 0.0)
    assert Exit(0) not in node.step([clock(1, (A,), end=True, reason="duration")], 0.1)
    assert Exit(0) in node.step([], 1.2)  # no news of the world's token, no later clock: the end stands


def test_an_end_claiming_a_far_tick_is_not_the_end_once_the_world_ticks_on() -> None:
    """A forged end may claim a tick the world has not reached: the world's next clock refutes it all the same
    (it stood as the newest clock and ended the agent once the world was quiet for end_confirm_s)."""
    node = started(peers=(), timing=dataclasses.replace(T, end_confirm_s=1.0))
    node.step([clock(0, (A,)), state(0, 100.0, 0.0)], 0.0)
    assert Exit(0) not in node.step([clock(50, (A,), end=True, reason="duration")], 0.1)
    node.step([clock(1, (A,)), state(1, 100.0, 0.0)], 0.2)  # the world goes on
    assert Exit(0) not in node.step([], 1.5)  # quiet a while (a stall shorter than world_silence_s)


def test_while_waiting_the_node_logs_what_it_lacks(caplog: pytest.LogCaptureFixture) -> None:
    node = started(peers=(B,))
    node.step([clock(0, (A, B)), state(0, 100.0, 0.0), beacon(B, 0, 105.0, 0.0)], 0.0)
    assert "no state yet" in node.waiting_for()
    with caplog.at_level("INFO", logger="reconswarm.agent"):
        node.step([], T.waiting_log_s + 0.1)
    assert "tick 1: no state yet (newest state 0, newest clock 0)" in caplog.text
    node.step([beacon(B, 1, 105.0, 0.0, rev=3), state(1, 100.0, 0.0)], T.waiting_log_s + 0.2)
    assert node.waiting_for() == "tick 1: waiting for clock"
    node.step([clock(1, (A, B))], T.waiting_log_s + 0.3)
    assert node.k == 0 and node.waiting_for() == "tick 1: waiting for obstacle sets of [2]"


def test_dropped_messages_are_counted_for_the_report_not_the_beacon() -> None:
    node = started(peers=())
    out = node.step([Invalid("k", "bad"), Invalid("k", "bad"), clock(0, (A,)), state(0, 100.0, 0.0)], 0.0)
    assert node.rejected == 2  # (the link's report carries it: reconswarm/net/trust/gate.py)
    assert beacons(out) == [wire.Beacon(A, 0, 0.0, 100.0, 0.0, RADIUS[A], 0)]  # no telemetry on the beacon


def test_a_robot_lost_out_of_hearing_is_an_obstacle_once_the_worlds_scan_reports_it_held() -> None:
    """With cells an agent hears only its neighbourhood: a peer lost far away was never heard. When its held
    robot comes within range, the world's scan reports it, and from then on it is a static obstacle."""
    node = started(peers=(B, C))
    node.step([left(C)], 0.0)  # C's agent is gone; we never had a beacon of it
    held = wire.Scan(A, 0, 0.0, (), ((C, 104.0, 0.0),))
    out = node.step([clock(0, (A, B)), state(0, 100.0, 0.0, scan=held), beacon(B, 0, 110.0, 0.0)], 0.01)
    ref = AgentBrain(S, A)
    want = reference(0, (100.0, 0.0), [Peer(B, 110.0, 0.0, RADIUS[B]), Peer(C, 104.0, 0.0, RADIUS[C])], brain=ref)
    assert [(c.k, c.v_mps, c.omega_radps) for c in cmds(out)] == [(0, *want)]
    assert want != reference(0, (100.0, 0.0), [Peer(B, 110.0, 0.0, RADIUS[B])])  # C's robot does push us
    out = node.step([clock(1, (A, B)), state(1, 100.05, 0.0), beacon(B, 1, 110.0, 0.0)], 0.06)  # no scan now
    want = reference(1, (100.05, 0.0), [Peer(B, 110.0, 0.0, RADIUS[B]), Peer(C, 104.0, 0.0, RADIUS[C])], brain=ref)
    assert [(c.k, c.v_mps, c.omega_radps) for c in cmds(out)] == [(1, *want)]  # still there: held robots do not move
    assert node.guessed_k == -1


def test_a_dead_peer_kept_alive_by_a_forged_token_is_still_an_obstacle() -> None:
    """An outsider keeps a token on a dead agent's key: by its membership the peer lives, but the world (whose
    clock a forged token does not change) counts it gone and holds its robot. Its last position and the
    world's report of the held robot both keep it an obstacle; it is not waited for."""
    node = started(peers=(B, C))
    node.step([clock(0), state(0, 100.0, 0.0), beacon(B, 0, 110.0, 0.0), beacon(C, 0, 104.0, 0.0)], 0.0)
    # C's agent dies; a token for C stays (forged), so no left(C). The world's clock of tick 1 lacks C.
    held = wire.Scan(A, 1, DT, (), ((C, 104.0, 0.0),))
    out = node.step([clock(1, (A, B)), state(1, 100.05, 0.0, scan=held), beacon(B, 1, 110.0, 0.0)], 0.06)
    ref = AgentBrain(S, A)
    reference(0, (100.0, 0.0), [Peer(B, 110.0, 0.0, RADIUS[B]), Peer(C, 104.0, 0.0, RADIUS[C])], brain=ref)
    want = reference(1, (100.05, 0.0), [Peer(B, 110.0, 0.0, RADIUS[B]), Peer(C, 104.0, 0.0, RADIUS[C])], brain=ref)
    assert [(c.k, c.v_mps, c.omega_radps) for c in cmds(out)] == [(1, *want)]
    out = node.step([clock(2, (A, B)), state(2, 100.1, 0.0), beacon(B, 2, 110.0, 0.0)], 0.11)  # no beacon of C at 1
    want = reference(2, (100.1, 0.0), [Peer(B, 110.0, 0.0, RADIUS[B]), Peer(C, 104.0, 0.0, RADIUS[C])], brain=ref)
    assert [(c.k, c.v_mps, c.omega_radps) for c in cmds(out)] == [(2, *want)]
    assert node.guessed_k == -1  # gone by the world's count: not a guess


def test_lockstep_a_live_peer_that_left_our_cells_while_we_were_frozen_is_not_a_ghost() -> None:
    """Lockstep: frozen (SIGSTOP) while the swarm moved on, we come back with our peers' last beacons from before.
    A peer the world's clock still counts alive (it commands) whose beacon we have not heard for peer_silent_s
    of ticks left the cells we listen to (a near peer beacons every tick): its old position is dropped, not
    planned with for ever (seen: two agents of a frozen host stood still for 210 s beside ghosts)."""
    node, ref = started(peers=(B, C)), AgentBrain(S, A)
    node.step([clock(0), state(0, 100.0, 0.0), beacon(B, 0, 104.0, 0.0), beacon(C, 0, 110.0, 0.0)], 0.0)
    reference(0, (100.0, 0.0), [Peer(B, 104.0, 0.0, RADIUS[B]), Peer(C, 110.0, 0.0, RADIUS[C])], brain=ref)
    k, now = 80, 20.0  # back 20 s later: the world went on without us; C said nothing since tick 0
    out = node.step([clock(k), state(k, 100.0, 0.0), beacon(B, k, 104.0, 0.0)], now)
    ghost = [Peer(B, 104.0, 0.0, RADIUS[B]), Peer(C, 110.0, 0.0, RADIUS[C])]
    assert [c.k for c in cmds(out)] == [k]  # (acting without C at once: silent for longer than peer_silent_s)
    reference(k, (100.0, 0.0), ghost, brain=ref)  # (this tick still plans with C's last position: a guess)
    out = node.step([clock(k + 1), state(k + 1, 100.0, 0.0), beacon(B, k + 1, 104.0, 0.0)], now + 0.05)
    want = reference(k + 1, (100.0, 0.0), [Peer(B, 104.0, 0.0, RADIUS[B])], brain=ref)
    assert [(c.k, c.v_mps, c.omega_radps) for c in cmds(out)] == [(k + 1, *want)]
    assert C not in node.h.last_seen
    assert want != reference(k + 1, (100.0, 0.0), ghost, brain=AgentBrain(S, A))  # (C's old place would push us)


def test_lockstep_a_live_peer_silent_for_fewer_ticks_is_still_where_last_heard() -> None:
    """The same peer silent for fewer than peer_silent_s of ticks keeps its last position (a late beacon, not a
    peer gone from our cells); one the world no longer counts alive stays where last seen as a lost robot."""
    node = started(peers=(B, C))
    node.step([clock(0), state(0, 100.0, 0.0), beacon(B, 0, 104.0, 0.0), beacon(C, 0, 110.0, 0.0)], 0.0)
    k = 40  # (a prune tick; 40 ticks < peer_silent_s / dt)
    node.step([clock(k), state(k, 100.0, 0.0), beacon(B, k, 104.0, 0.0)], 20.0)
    assert C in node.h.last_seen
    node = started(peers=(B, C))
    node.step([clock(0), state(0, 100.0, 0.0), beacon(B, 0, 104.0, 0.0), beacon(C, 0, 110.0, 0.0)], 0.0)
    node.step([clock(80, (A, B)), state(80, 100.0, 0.0), beacon(B, 80, 104.0, 0.0)], 20.0)  # C not counted: lost
    assert node.h.last_seen[C].px == 110.0


def test_a_stop_leaves_at_once_with_exit_0_whatever_else_came() -> None:
    """A signal (the runtime's Stop) ends the node's loop cleanly: exit 0, said to be a stop, and nothing of the
    batch after it is acted on (no beacon, no command)."""
    node = started()
    assert node.step([Stop(), clock(0), state(0, 100.0, 0.0)], 0.0) == [Exit(0, "stopped")]
    assert node.k == -1 and node.beacon_sent == -1
