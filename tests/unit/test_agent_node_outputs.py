"""The agent node's state machine (agent/node.py) case by case, from its mutation survivors (continued from
tests/unit/test_agent_node_cases.py): which ticks wait for what (a lost clock, the joining rule only for a first
tick mid-mission, a restarted peer's revisions), the exact revisions lockstep merges, every scan since the last
command, realtime's windows, and what goes out when (the obstacle set again after a new session or in a new
home cell, the cells after a command, a single beacon per tick), the virtual leader's union and the deadlock
perturbation."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from agent.brain import AgentBrain
from agent.neighbours import Cells
from reconswarm.net.wire import wire
from reconswarm.scenario.model import PlannerKind
from tests.support import joined, world_token
from tests.unit.solo import SoloNode
from tests.unit.test_agent_node import DT, A, B, C, S, T, beacon, beacons, clock, cmds, started, state
from tests.unit.test_agent_node_cases import HULL, RT, Hulls, Ref, peer, sets, vw

# ------------------------------------------------------------------------------------ ticks and waits

def test_a_second_lost_clock_is_waited_for_from_its_own_state() -> None:
    node = started(peers=())
    node.step([clock(0, (A,)), state(0, 100.0, 0.0)], 0.0)
    node.step([state(1, 100.0, 0.0)], 0.1)  # clock 1 lost
    assert [c.k for c in cmds(node.step([], 0.1 + T.agent_wait_timeout_s + 0.01))] == [1]
    t2 = 0.2 + T.agent_wait_timeout_s
    node.step([state(2, 100.0, 0.0)], t2)  # clock 2 lost too
    assert not cmds(node.step([], t2 + 0.5 * T.agent_wait_timeout_s))
    assert [c.k for c in cmds(node.step([], t2 + T.agent_wait_timeout_s + 0.01))] == [2]


def test_the_joining_rule_holds_only_for_a_first_tick_mid_mission() -> None:
    """A first tick after 0 waits for every peer's cached set (any revision, far ones too) and merges them all;
    tick 0, and any tick after our first command, waits only for the sets of the peers within link range."""
    far: Hulls = {"hexagon": ((600.0, 0.0), (601.0, 1.0), (601.0, -1.0))}
    node = started(peers=(B,))  # tick 0: B is 50 m away (beyond link range), announcing a set we have
    node.step([wire.ObstacleSet(B, 0, 1, far), clock(0, (A, B)), state(0, 100.0, 0.0)], 0.0)
    node.step([beacon(B, 0, 150.0, 0.0, rev=1)], 0.01)
    assert node.k == 0 and "hexagon" not in node.brain.obstacle_sets()  # not linked: not merged
    node = started(peers=(B,))  # the same with B's set not in: not waited for, at tick 0 or after
    node.step([clock(0, (A, B)), state(0, 100.0, 0.0), beacon(B, 0, 150.0, 0.0, rev=2)], 0.0)
    assert node.k == 0
    node.step([clock(1, (A, B)), state(1, 100.0, 0.0), beacon(B, 1, 150.0, 0.0, rev=3)], 0.05)
    assert node.k == 1 and node.guessed_k == -1
    node = started(peers=(B,))  # first tick 1: joining
    node.step([clock(1, (A, B)), state(1, 100.0, 0.0), beacon(B, 1, 150.0, 0.0, rev=1)], 0.0)
    assert node.k == -1  # B's cached set first
    node.step([wire.ObstacleSet(B, 0, 1, far)], 0.01)
    assert node.k == 1 and "hexagon" in node.brain.obstacle_sets()


def test_a_restarted_peer_counting_its_revisions_again_is_not_waited_for() -> None:
    """A peer restarted counts its revisions from 1 again: a revision at or below the one we merged is static
    knowledge we hold (its new set need not come before we act)."""
    node = started(peers=(B,))
    hulls = {r: wire.ObstacleSet(B, r, r, {"diamond": ((130.0 + r, 0.0), (131.0, 1.0), (131.0, -1.0))}) for r in (1, 2)}
    for k in range(21):
        rev = 1 if k < 10 else 2
        batch: list = [clock(k, (A, B)), state(k, 100.0, 0.0), beacon(B, k, 105.0, 0.0, rev)]
        if k in (0, 10):
            batch.append(hulls[rev])
        node.step(batch, k * 0.01)
    assert node.k == 20 and list(node.sets[B]) == [2]
    node.step([clock(21, (A, B)), state(21, 100.0, 0.0), beacon(B, 21, 105.0, 0.0, 1)], 0.3)  # B restarted
    assert node.k == 21 and node.guessed_k == -1


def test_lockstep_merges_the_revision_the_beacon_announces_not_a_newer_one() -> None:
    near = {r: wire.ObstacleSet(B, 0, r, {f"o{r}": ((108.0 + 2 * r, 5.0), (109.0 + 2 * r, 6.0), (109.0 + 2 * r, 4.0))})
            for r in (1, 2)}
    node = started(peers=(B,))
    out = node.step([near[1], near[2], clock(0, (A, B)), state(0, 100.0, 0.0), beacon(B, 0, 110.0, 0.0, rev=1)], 0.0)
    ref = Ref()
    shared = [{"o1": np.array(near[1].obstacles["o1"])}]
    assert vw(out) == [ref.tick(0, (100.0, 0.0), [peer(B, 110.0)], shared=shared)]
    assert set(node.brain.obstacle_sets()) == {"o1"}


def test_a_wait_given_up_still_merges_the_linked_peers_sets() -> None:
    node = started(peers=(B, C))  # C never answers; B is linked and its set is in
    hull = wire.ObstacleSet(B, 0, 1, {"o": ((112.0, 5.0), (113.0, 6.0), (113.0, 4.0))})
    node.step([hull, clock(0), state(0, 100.0, 0.0), beacon(B, 0, 110.0, 0.0, rev=1)], 0.0)
    node.step([], T.agent_wait_timeout_s + 0.01)
    assert node.k == 0 and node.guessed_k == 0 and "o" in node.brain.obstacle_sets()


def test_each_tick_plans_with_every_scan_since_the_last_command() -> None:
    node = started(peers=())
    node.step([clock(0, (A,)), state(0, 100.0, 0.0)], 0.0)
    one = wire.Scan(A, 1, DT, ((130.0, 0.0, "one"), (131.0, 1.0, "one"), (131.0, -1.0, "one")))
    two = wire.Scan(A, 2, 2 * DT, ((130.0, 20.0, "two"), (131.0, 21.0, "two"), (131.0, 19.0, "two")))
    node.step([clock(1, (A,)), state(1, 100.0, 0.0, scan=one)], 0.05)
    assert node.k == 1 and set(node.brain.obstacle_sets()) == {"one"}  # lockstep: tick 1's own scan
    node.step([clock(3, (A,), **RT), state(2, 100.0, 0.0, scan=two), state(3, 100.0, 0.0)], 0.1)
    node.step([], node.wake_at_s() or 0.2)
    assert node.k == 3 and set(node.brain.obstacle_sets()) == {"one", "two"}  # realtime skipped tick 2: its scan too


def test_realtime_merges_the_newest_set_of_a_linked_peer_even_when_it_comes_late() -> None:
    node = started(peers=(B,))
    node.step([clock(0, (A, B), **RT), state(0, 100.0, 0.0), beacon(B, 0, 110.0, 0.0, rev=1)], 0.0)
    assert node.k == 0 and node.brain.obstacle_sets() == {}  # B's set has not come yet
    node.step([wire.ObstacleSet(B, 0, 1, {"o": ((112.0, 5.0), (113.0, 6.0), (113.0, 4.0))})], 0.001)
    node.step([clock(1, (A, B), **RT), state(1, 100.0, 0.0), beacon(B, 1, 110.0, 0.0, rev=1)], 0.005)
    assert node.k == 1 and set(node.brain.obstacle_sets()) == {"o"}


# ------------------------------------------------------------------------------------------- outputs

def test_nothing_goes_out_before_the_mission_and_no_timer_is_set() -> None:
    node = SoloNode(S, A, 0.0, T)
    assert node.wake_at_s() is None
    assert node.step([joined(A)], 0.0) == []  # (no obstacle set of revision 0)
    node.step([world_token(False)], 0.5)
    assert node.step([world_token(True)], 1.0) == []  # a world stalled before the start: nothing to do


def test_a_new_session_publishes_the_set_once_at_the_last_commanded_tick() -> None:
    node = started(peers=())
    out = node.step([clock(0, (A,)), state(0, 100.0, 0.0, scan=wire.Scan(A, 0, 0.0, HULL))], 0.0)
    grown = sets(out)
    assert [(s.id, s.k, s.rev) for s in grown] == [(A, 0, 1)]  # knowledge grew at tick 0
    assert [c.id for c in cmds(out)] == [A]
    # The mission's first tick: only our cells, from our state on (before our beacon).
    assert isinstance(out[0], Cells) and out[0].listen is not None and isinstance(out[1], wire.Beacon)
    node.reconnected(1.0)
    out = node.step([], 1.1)
    assert [(s.id, s.k, s.rev, set(s.obstacles)) for s in sets(out)] == [(A, 0, 1, {"diamond"})]
    assert sets(node.step([], 1.2)) == []  # once


def test_a_new_home_cell_gets_the_set_again_a_new_listening_cell_does_not() -> None:
    node = started(peers=())
    node.step([clock(0, (A,)), state(0, 100.0, 0.0, scan=wire.Scan(A, 0, 0.0, HULL))], 0.0)
    out = node.step([clock(1, (A,)), state(1, 112.0, 0.0)], 0.05)  # a new home cell: its cache lacks our set
    assert [type(o) for o in out][:3] == [Cells, wire.ObstacleSet, wire.Beacon]
    assert [(s.id, s.k, s.rev) for s in sets(out)] == [(A, 0, 1)]  # (as of our last command)
    home = node.nb.grid.cell_of(112.0, 0.0)
    out = node.step([clock(2, (A,)), state(2, 120.0, 20.0)], 0.1)  # same home cell, more cells to listen to
    assert isinstance(out[0], Cells) and out[0].home == home
    assert [type(o) for o in out][:3] == [Cells, wire.Beacon, wire.Cmd] and sets(out) == []
    node = started(peers=())  # knowing nothing: no set to put
    node.step([clock(0, (A,)), state(0, 100.0, 0.0)], 0.0)
    out = node.step([clock(1, (A,)), state(1, 112.0, 0.0)], 0.05)
    assert sets(out) == [] and isinstance(out[0], Cells)


def test_a_stuck_ticks_set_goes_again_as_of_that_tick() -> None:
    node = started(peers=(B,))
    node.step([clock(0, (A, B)), state(0, 100.0, 0.0, scan=wire.Scan(A, 0, 0.0, HULL)), beacon(B, 0, 140.0, 0.0)],
              0.0)
    node.step([clock(1, (A, B)), state(1, 100.0, 0.0)], 1.0)
    out = node.step([], 1.0 + T.beacon_again_s + 0.01)
    assert [(s.id, s.k, s.rev) for s in sets(out)] == [(A, 1, 1)]


def test_realtime_one_beacon_and_one_command_per_tick() -> None:
    node = started(peers=(B,))
    out = node.step([clock(0, (A, B), **RT), state(0, 100.0, 0.0)], 0.0)
    assert [b.k for b in beacons(out)] == [0] and not cmds(out)
    assert node.step([], 0.001) == []  # still waiting for B: no second beacon
    out = node.step([beacon(B, 0, 110.0, 0.0)], 0.002)
    assert [c.k for c in cmds(out)] == [0]
    assert node.step([beacon(B, 0, 110.0, 0.0)], 0.003) == []  # tick 0 is done: no second command
    out = node.step([state(1, 100.0, 0.0), beacon(B, 1, 110.0, 0.0)], 0.004)
    assert [c.k for c in cmds(out)] == [1] and node.guessed_k == -1  # (realtime says no guess: not lockstep)


def test_realtime_acts_a_fraction_of_a_period_after_the_state() -> None:
    node = started(peers=(B,))
    out = node.step([clock(0, (A, B), mode="realtime", speed=1.0), state(0, 100.0, 0.0)], 0.5)  # B heard lately
    assert not cmds(out) and node.wake_at_s() == pytest.approx(0.5 + T.realtime_act_fraction * DT)
    node = started(peers=(B,))  # speed 0: as fast as it can, so at once on whatever it has
    out = node.step([clock(0, (A, B), mode="realtime", speed=0.0), state(0, 100.0, 0.0)], 0.5)
    assert [c.k for c in cmds(out)] == [0] and node.wake_at_s() is None


def test_the_waiting_log_runs_before_any_state() -> None:
    node = started(peers=())
    assert "no state yet" in node.waiting_for()
    node.step([clock(0, (A,))], 0.0)
    assert node.step([], T.waiting_log_s + 0.1) == []  # (logs what it lacks; no state to name yet)
    assert "no state yet" in node.waiting_for()


def test_realtime_after_the_first_command_plans_with_the_scans_of_skipped_ticks() -> None:
    node = started(peers=())
    node.step([clock(0, (A,), **RT), state(0, 100.0, 0.0)], 0.0)
    assert node.k == 0
    one = wire.Scan(A, 1, DT, ((130.0, 0.0, "one"), (131.0, 1.0, "one"), (131.0, -1.0, "one")))
    node.step([clock(2, (A,), **RT), state(1, 100.0, 0.0, scan=one), state(2, 100.0, 0.0)], 0.01)
    node.step([], node.wake_at_s() or 0.1)
    assert node.k == 2 and set(node.brain.obstacle_sets()) == {"one"}  # tick 1 skipped, its scan not


@pytest.mark.parametrize("mode", ["lockstep", "realtime"])
def test_the_virtual_leader_merges_every_peers_set_into_the_union(mode: str) -> None:
    s = dataclasses.replace(S, planner=dataclasses.replace(S.planner, kind=PlannerKind.VIRTUAL_LEADER))
    node = SoloNode(s, A, 0.0, T)
    node.step([joined(A), joined(B)], 0.0)
    kw = RT if mode == "realtime" else {}
    far = wire.ObstacleSet(B, 0, 1, {"hexagon": ((600.0, 0.0), (601.0, 1.0), (601.0, -1.0))})
    node.step([far, clock(0, (A, B), **kw), state(0, 100.0, 0.0), beacon(B, 0, 900.0, 0.0, rev=1)], 0.0)
    node.step([], node.wake_at_s() or 0.01)
    assert node.k == 0
    assert "hexagon" in dict(node.brain.union.sorted_items())  # far beyond link range: the union has it
    assert "hexagon" not in node.brain.obstacle_sets()  # (our own knowledge merges linked peers' sets only)


def test_with_the_deadlock_perturbation_on_the_brain_is_fed_each_tick() -> None:
    """perturbation_mps > 0: the stall detector keeps a window of ticks (stall_window_s = 5 s, 100 ticks) and
    perturbs a robot that made no progress over it. Standing still for 120 ticks, the node commands every tick
    as the brain fed that tick does, and the perturbation comes in (the command changes with no new input)."""
    s = dataclasses.replace(S, planner=dataclasses.replace(S.planner, perturbation_mps=0.5))
    node = started(node_s=s, peers=())
    ref = AgentBrain(s, A)
    got, want = [], []
    for k in range(120):
        got += vw(node.step([clock(k, (A,)), state(k, 100.0, 0.0)], k * 0.01))
        u, _ = ref.tick(k, np.array([100.0, 0.0]), {}, [], [])
        want.append((k, *ref.inputs(u, 0.0)))
    assert got == want and got[-1][1:] != got[0][1:]
