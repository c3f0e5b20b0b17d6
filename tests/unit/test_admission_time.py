"""Admission's reach bounds come from trusted time: the newest tick of the world's clock the receiver holds
(its gate's), at most `CLOCK_LEAD_TICKS` ahead (a peer's beacon of tick k+1 can come just before the world's
clock of k+1), or before any clock, the mission's last tick; never from the time a message claims. A beacon
claiming t = 1e300 (stamped with its agent's session id, overheard in open mode) neither passes nor widens the
next one's bound; a claimed time going back widens nothing either."""

from __future__ import annotations

from reconswarm.net.trust.admission import CLOCK_LEAD_TICKS, Admission, IntrusionKind
from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire import wire
from reconswarm.net.wire.keys import Keys
from reconswarm.scenario.model import load
from tests.support import PAPER

S = load(PAPER)
DT = S.meta.dt_s
KEYS = Keys("paper-0a1b2c")
WORLD, A8 = "world-zid", "host-zid"
IDS = tuple(a.id for a in S.agents)
K = IntrusionKind
BKEY = KEYS.host_beacons((0, 0), 8)
STEP = Admission(S).reach_m(DT)  # how far a beacon may move in one tick (u_max dt + 1 m)


def clock(k: int) -> wire.Clock:
    return wire.Clock(k, k * DT, IDS)


def beacon(k: int, px: float, py: float = 20.0, t: float | None = None) -> wire.Beacon:
    return wire.Beacon(8, k, k * DT if t is None else t, px, py, float(S.radii[S.agent_index(8)]))


def gate_at(k: int) -> Gate:
    g = Gate(S, "agent-3")
    assert g.admit(clock(k), WORLD, KEYS.clock, 0.0)
    return g


def test_a_beacon_claiming_t_1e300_is_refused_and_widens_nothing() -> None:
    """Agent 8 at x = 40 at tick 2000 (t = 100 s); beacons in its name (its host's session) claiming t = 1e300,
    or a tick 10^6 ahead, 3 steps away: refused. Agent 8's own next beacon is admitted, and a jump of more than
    a step at the next tick is refused, as it would have been had nothing been forged."""
    g = gate_at(2000)
    assert g.admit(beacon(2000, 40.0), A8, BKEY, 0.0)
    assert not g.admit(beacon(2001, 40.0 + 3 * STEP, t=1e300), A8, BKEY, 0.1)
    assert not g.admit(beacon(10**12, 40.0 + 3 * STEP, t=1e300), A8, BKEY, 0.1)
    assert not g.admit(beacon(2001 + 10**6, 40.0 + 3 * STEP), A8, BKEY, 0.1)
    assert g.tally.as_rows()[0][:3] == (K.POSITION.value, A8, 3)
    assert g.admit(beacon(2001, 40.5), A8, BKEY, 0.2)
    assert g.admit(clock(2001), WORLD, KEYS.clock, 0.2)
    assert not g.admit(beacon(2002, 40.5 + STEP + 0.1), A8, BKEY, 0.3)
    assert g.admit(beacon(2002, 40.5 + 0.9 * STEP), A8, BKEY, 0.3)


def test_a_beacon_ahead_of_the_receivers_clock_by_the_lead_at_most_is_admitted() -> None:
    adm = Admission(S)
    assert adm.check_beacon(beacon(100 + CLOCK_LEAD_TICKS, 40.0), A8, BKEY, 0.0, world_k=100) is None
    got = adm.check_beacon(beacon(101 + CLOCK_LEAD_TICKS, 40.0), A8, BKEY, 0.0, world_k=100)
    assert got is not None and got.kind is K.POSITION and "ahead of the world's tick 100" in got.detail
    last = round(S.meta.duration_s / DT)  # no clock held yet: the mission's last tick bounds it
    assert Admission(S).check_beacon(beacon(last, 40.0), A8, BKEY, 0.0) is None
    got = Admission(S).check_beacon(beacon(last + 1, 40.0), A8, BKEY, 0.0)
    assert got is not None and "after the mission's last" in got.detail


def test_a_claimed_time_going_back_widens_no_bound() -> None:
    """Agent 8 at tick 2000; a beacon of tick 0 (t = 0, consistent with it) far away: |t - t0| = 100 s would
    allow it; time going back allows only what the receiver's clock ran since (here nothing: the margin)."""
    g = gate_at(2000)
    assert g.admit(beacon(2000, 40.0), A8, BKEY, 0.0)
    assert not g.admit(beacon(0, 40.0 + STEP), A8, BKEY, 0.1)
    assert g.admit(beacon(1999, 40.5), A8, BKEY, 0.1)  # (a beacon come late, say)


def test_the_receivers_clock_bounds_the_time_between_two_beacons_whatever_they_claim() -> None:
    """A lagging agent's beacons (realtime): tick 1000 seen at the receiver's tick 2000, then tick 2000 at 2001:
    it may have moved for 1000 ticks (its ticks moved on). A forged beacon whose tick is stored ahead (by the lead
    at most) holds the agent's own next beacons back no longer than the receiver's clock takes to catch up."""
    g = gate_at(2000)
    assert g.admit(beacon(1000, 40.0), A8, BKEY, 0.0)
    assert g.admit(clock(2001), WORLD, KEYS.clock, 0.1)
    assert g.admit(beacon(2000, 40.0 + 500 * STEP), A8, BKEY, 0.1)
    ahead = 2001 + CLOCK_LEAD_TICKS
    assert g.admit(beacon(ahead, 40.0 + 500 * STEP + 0.9 * STEP * (ahead - 2000)), A8, BKEY, 0.2)  # forged
    honest = 40.0 + 500 * STEP + 0.9 * STEP
    assert not g.admit(beacon(2002, honest), A8, BKEY, 0.3)  # (the receiver's clock has not run on yet)
    for k in range(2002, ahead + 1):
        g.admit(clock(k), WORLD, KEYS.clock, 0.3)
    assert g.admit(beacon(ahead + 1, honest + 0.9 * STEP), A8, BKEY, 0.4)


def test_odometry_claiming_a_far_future_time_gets_the_bound_of_the_receivers_clock() -> None:
    g = gate_at(2000)
    key = KEYS.host(8, "state")
    assert g.admit_odometry(wire.State(8, 2000, 100.0, 40.0, 20.0, 0.0, 40.0, 20.0), WORLD, key, 0.0)
    far = 40.0 + (1 + CLOCK_LEAD_TICKS) * STEP
    assert not g.admit_odometry(wire.State(8, 2001, 1e300, far, 20.0, 0.0, far, 20.0), WORLD, key, 0.1)
    assert g.admit_odometry(wire.State(8, 2001, 100.05, 40.5, 20.0, 0.0, 40.5, 20.0), WORLD, key, 0.2)
