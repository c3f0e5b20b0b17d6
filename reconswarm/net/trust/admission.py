"""Admission: can a well-formed message belong to this run? Pure rules, no zenoh.

The wire decoders (wire.py) refuse what is malformed. This module refuses what is well formed but that the
run cannot contain, from what the scenario says and what has been seen; each refusal is an `Intrusion`,
which the receiver drops, counts (`tally.IntrusionTally`) and logs. The rules:

- agents: only the scenario's ids; a beacon's radius is the scenario's radius for that id; a position lies
  inside the scenario's extent grown by what the fastest possible motion covers by then, and within the
  same bound of that agent's previous beacon (`reach_m`). "Then" is trusted time: a beacon's t is its
  tick's (k dt) and its tick no later than the newest tick of the world's clock the receiver holds plus
  `CLOCK_LEAD_TICKS` (before any clock, the mission's last tick); the time between two beacons is the larger of
  how far the tick moved on (never back) and how far the receiver's clock did. A message's
  claimed time never widens its own bound beyond trusted time (nor, stored, the next one's); odometry's time
  is held to the same bound;
- obstacle sets: only the scenario's obstacle ids (so never more ids than it has); a hull has at most as
  many vertices as the sensor samples on that obstacle, and every vertex lies on the true obstacle's
  boundary within `HULL_TOL_M`: agents only share hulls of sensed contour points, which lie on the true
  boundary, so a shared hull is never larger than the real obstacle whoever sent it;
- commands: |u| at most `command_bound_mps` (what the planner can output with bounded repulsion) and for a
  tick the world has published; a ROS 2 cmd_vel, which a robot base holds as a twist, moves the head point
  no faster than that over the step's arc and turns at most half a turn in a step;
- the world's messages (clock, state, scan, truth): only from the world's session, pinned at its first
  clock; the clock keeps its mode and speed, t = k dt, and k is no later than the mission's last tick;
- an agent's messages (beacon, cmd): only from the session that agent speaks from (`Pins`, pinned at first
  sight; another session may take over only once the pinned one has been silent `repin_after_s`, as a
  restarted agent's new session does);
- membership (reconswarm/net/trust/membership.py, not here): an agent is alive while its liveliness token is there
  AND its own session's data keeps coming; a token anyone can declare decides nothing alone.

Sources are the publishers' zenoh session ids as their samples carry them: the id in the sample's
timestamp (`inbox.sample_source`), which every session of the run stamps (timestamping is on in all of
them; a router stamps what arrives unstamped with its own id). zenoh-python 1.10.2 also offers
`SourceInfo`, but only when the publisher sets it on each put (an unstable API that the advanced publisher
of obstacle sets does not take), and it is no harder to forge. In open mode any client on the port can
stamp a session id it has overheard, so these rules stop confused or naive clients and bound what a
malicious one can do (no unbounded force, no impossible obstacle, no unknown robot); they do not
authenticate. `--secure` (mutual TLS and access control) does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from reconswarm.geometry.plane import SAMPLE_SPACING_M, Edges, sample_boundary, signed_distance
from reconswarm.net.timing import TIMING
from reconswarm.net.wire import wire
from reconswarm.paper.planner import max_repulsion_speed
from reconswarm.plant.unicycle import arc_head_speed
from reconswarm.scenario.model import Scenario

HULL_TOL_M = 1e-3  # a shared vertex must lie within this of the true boundary (float error is ~1e-12 m)
RADIUS_RTOL = 1e-9
POSITION_MARGIN_M = 1.0
# How many ticks a beacon may lie ahead of the newest clock its receiver holds (a peer's beacon of tick k+1 comes
# after the world's clock of k+1 through one router; a few ticks of slack for priorities and co-hosted agents).
CLOCK_LEAD_TICKS = 4
COMMAND_TOL = 1e-9  # relative
UNATTRIBUTED = "unattributed"  # the source of a message that carries no publisher id
# Hull vertices remembered as checked (~100 bytes each: a few MB at most, however many distinct truthful
# hulls a flood sends; the paper's swarm shares ~500 distinct hulls over a whole mission, ~10k vertices).
HULL_VERTICES_KEPT = 65_536


class IntrusionKind(Enum):
    UNKNOWN_AGENT = "unknown_agent"  # an agent id the scenario does not have
    RADIUS = "radius"  # a beacon's radius differs from the scenario's
    POSITION = "position"  # a position the robot cannot have reached
    UNKNOWN_OBSTACLE = "unknown_obstacle"  # an obstacle id the scenario does not have
    HULL = "hull"  # a hull off the true obstacle, or with more vertices than can be sensed
    COMMAND = "command"  # a command above what the planner can output, or for a tick not yet published
    NOT_FROM_WORLD = "not_from_world"  # clock, state, scan or truth from a session other than the world's
    CLOCK = "clock"  # the world's clock changing mode or speed, or t != k dt
    IMPERSONATION = "impersonation"  # an agent's message from a session other than that agent's
    OVERSIZE = "oversize"  # an obstacle set larger than the scenario's full set (refused before decoding)
    CONFLICT = "conflicting_command"  # a second, different command for an agent's tick (someone else speaks for it)
    END = "end"  # an end of the mission that the world did not decide (later clocks, or the truth, contradict it)


@dataclass(frozen=True)
class Intrusion:
    kind: IntrusionKind
    source: str
    key: str
    detail: str


def command_bound_mps(s: Scenario) -> float:
    """The largest |u| the planner can output (eq. 7 with bounded repulsion), plus Remark 1's perturbation.

    Attraction: at most R_c k_att (outside B(p*, R_c) exactly that; inside k_att |e| which the scenario keeps
    below it for agents that start inside). Each repulsive term (every other agent, every obstacle) at most
    `max_repulsion_speed`. The virtual-leader benchmark adds the leader's velocity (its own attraction and
    obstacle repulsion) and the containment wall.
    """
    p = s.planner
    offsets = max((math.hypot(*a.offset_m) for a in s.agents), default=0.0)
    att = p.k_att * max(p.target_radius_m, p.target_radius_m + offsets)
    rep = max_repulsion_speed(p.psi_mps, p.d_safe_m, p.d_max_m)
    u = att + rep * (len(s.agents) - 1 + len(s.obstacles)) + p.perturbation_mps
    if p.kind == "virtual-leader":
        u += att + rep * len(s.obstacles) + rep
    if s.world.max_speed_mps > 0:
        u = max(u, s.world.max_speed_mps)
    return u


@dataclass
class Pins:
    """Which session speaks for whom: the world (pinned at its first clock) and each agent."""

    repin_after_s: float = TIMING.repin_after_s
    world: str | None = None
    agents: dict[int, tuple[str, float]] = field(default_factory=dict)  # id -> (source, last heard, wall s)

    def agent(self, agent_id: int, source: str, now: float) -> bool:
        """True if `source` speaks for the agent (pinning it if nobody does, or the pinned one fell silent)."""
        pinned = self.agents.get(agent_id)
        if pinned is None or pinned[0] == source or now - pinned[1] >= self.repin_after_s:
            if source == UNATTRIBUTED:
                return False
            self.agents[agent_id] = (source, now)
            return True
        return False


class HullChecks:
    """Whether a shared hull lies on its obstacle's boundary: a question about the hull alone (whoever sent it,
    whoever receives it), so the agents of one process ask one `HullChecks` and a hull that many peers share,
    or that every co-hosted agent receives, is measured once. A refused hull is never kept; the memory of
    hulls found good is bounded (`vertices_kept`)."""

    def __init__(self, s: Scenario, vertices_kept: int = HULL_VERTICES_KEPT) -> None:
        self.polygons = {o.id: s.polygon(k) for k, o in enumerate(s.obstacles)}
        self.edges = {o: Edges.of([poly]) for o, poly in self.polygons.items()}
        self.max_vertices = {o: int(sample_boundary(poly, SAMPLE_SPACING_M).shape[0])
                             for o, poly in self.polygons.items()}
        self.ok: set[tuple[str, tuple[tuple[float, float], ...]]] = set()
        self._kept_vertices, self._keep_vertices = 0, vertices_kept

    def problem(self, oid: str, hull: tuple[tuple[float, float], ...]) -> str | None:
        """None if every vertex of `hull` (of a known obstacle id) lies on that obstacle's boundary and there are no
        more than can be sensed; else what is wrong."""
        if len(hull) > self.max_vertices[oid]:
            return f"{len(hull)} vertices, at most {self.max_vertices[oid]} can be sensed"
        if not hull or (oid, hull) in self.ok:
            return None
        pts = np.asarray(hull, dtype=np.float64).reshape(-1, 2)
        d = signed_distance(pts[:, 0:1], pts[:, 1:2], self.edges[oid], normals=False)  # (P, 1)
        worst = float(np.abs(d).max())
        if not worst <= HULL_TOL_M:
            return f"a vertex {worst:.6g} m off the obstacle's boundary"
        if self._kept_vertices + len(hull) > self._keep_vertices:
            self.ok.clear()
            self._kept_vertices = 0
        self.ok.add((oid, hull))
        self._kept_vertices += len(hull)
        return None


class Admission:
    """The rules above for one scenario; `check_*` return None (admitted) or the Intrusion.

    hulls: the process's `HullChecks`, shared by its agents' admissions (None: one of its own, remembering at most
    `hull_vertices_kept` vertices)."""

    def __init__(self, s: Scenario, pins: Pins | None = None, hull_vertices_kept: int = HULL_VERTICES_KEPT,
                 hulls: HullChecks | None = None) -> None:
        self.s = s
        self.pins = pins or Pins()
        self.radius = {a.id: a.radius_m for a in s.agents}
        self.head_offset = {a.id: float(a.head_offset_m) for a in s.agents}
        self.last_tick = round(s.meta.duration_s / s.meta.dt_s)  # the world's last (simworld/world.py: n_ticks)
        self.hulls = hulls or HullChecks(s, hull_vertices_kept)
        self.polygons, self.max_vertices = self.hulls.polygons, self.hulls.max_vertices
        self.u_max = command_bound_mps(s)
        # The largest obstacle set the run can send: every obstacle with every sensed vertex, as msgpack
        # (a map of id -> list of [x, y] float64 pairs, 19 bytes a vertex, plus headers and the fields).
        self.max_set_bytes = 128 + sum(len(o.encode()) + 16 + 19 * n for o, n in self.max_vertices.items())
        # The scenario's extent: starts (body centres; heads lie within head_offset), slots, obstacles.
        pts = [s.starts, np.array(s.target_m)[None, :] + s.offsets, *self.polygons.values()]
        allp = np.concatenate([p.reshape(-1, 2) for p in pts])
        grow = float(s.head_offsets.max(initial=0.0)) + POSITION_MARGIN_M
        self.lo = allp.min(axis=0) - grow
        self.hi = allp.max(axis=0) + grow
        self.clock_mode: tuple[str, float] | None = None
        # id -> (t, px, py, the receiver's tick then) of the last admitted beacon; of its robot's odometry
        self.last_beacon: dict[int, tuple[float, float, float, int]] = {}
        self.last_odom: dict[int, tuple[float, float, float, int]] = {}
        self.cmds: dict[tuple[int, int], tuple[float, float]] = {}  # (id, k) -> (v, ω) admitted, recent ticks

    # -- helpers -------------------------------------------------------------------------------------

    @staticmethod
    def _arc_speed(v_mps: float, omega_radps: float, head_offset_m: float, dt_s: float) -> float:
        """The head point's speed over a step under a twist held (unicycle.arc_head_speed); not finite: inf."""
        if not (math.isfinite(v_mps) and math.isfinite(omega_radps)):
            return math.inf
        return arc_head_speed(v_mps, omega_radps, head_offset_m, dt_s)

    def reach_m(self, dt_s: float) -> float:
        """How far a head point can move in dt_s of simulated time (|ṗ| = |u| for the unicycle's head)."""
        return self.u_max * max(0.0, dt_s) + POSITION_MARGIN_M

    def trusted_t(self, world_k: int) -> float:
        """The latest simulated time a message can be of: the receiver's newest clock (tick world_k; -1: none
        yet) plus `CLOCK_LEAD_TICKS`, and never after the mission's last tick."""
        return min(self.last_tick, self.last_tick if world_k < 0 else world_k + CLOCK_LEAD_TICKS) * self.s.meta.dt_s

    def _elapsed(self, t: float, world_k: int, last: tuple[float, float, float, int]) -> float:
        """Simulated time an agent can have moved for since its previous admitted message `last` (t0, x, y, the
        receiver's tick then): how far the message's (trusted-bounded) time moved on, never back, or how far the
        receiver's own clock did (an honest message's time is true, so the first bounds it; the second undoes a
        forged one's time stored ahead within a few ticks); whichever is larger."""
        t0, _x, _y, k0 = last
        ran = (world_k - k0) * self.s.meta.dt_s if world_k >= 0 and k0 >= 0 else 0.0
        return max(0.0, t - t0, ran)

    def _position(self, px: float, py: float, t: float) -> str | None:
        r = self.reach_m(t)
        if not (self.lo[0] - r <= px <= self.hi[0] + r and self.lo[1] - r <= py <= self.hi[1] + r):
            return f"({px:.6g}, {py:.6g}) outside the reachable area at t = {t:.6g} s"
        return None

    def _agent(self, agent_id: int, source: str, key: str, now: float) -> Intrusion | None:
        if agent_id not in self.radius:
            return Intrusion(IntrusionKind.UNKNOWN_AGENT, source, key, f"agent {agent_id} is not in the scenario")
        if not self.pins.agent(agent_id, source, now):
            who = self.pins.agents.get(agent_id, ("nobody", 0.0))[0]
            return Intrusion(IntrusionKind.IMPERSONATION, source, key, f"agent {agent_id} speaks from session {who}")
        return None

    # -- agent messages -------------------------------------------------------------------------------

    def check_beacon(self, b: wire.Beacon, source: str, key: str, now: float, world_k: int = -1) -> Intrusion | None:
        """world_k: the newest tick of the world's clock the receiver holds (-1: none yet)."""
        if b.id not in self.radius:
            return Intrusion(IntrusionKind.UNKNOWN_AGENT, source, key, f"agent {b.id} is not in the scenario")
        want = self.radius[b.id]
        if abs(b.radius - want) > RADIUS_RTOL * max(1.0, want):
            return Intrusion(IntrusionKind.RADIUS, source, key, f"radius {b.radius:.6g} m, the scenario's is {want} m")
        dt = self.s.meta.dt_s
        t = b.k * dt  # (the tick's time: what the beacon claims as t must be it)
        bad = None
        if not abs(b.t - t) <= 1e-9 * max(1.0, abs(t)):
            bad = f"t = {b.t:.9g} s at tick {b.k} (dt {dt} s)"
        elif not t <= self.trusted_t(world_k) + 1e-9:
            bad = (f"tick {b.k} ahead of the world's tick {world_k} by more than {CLOCK_LEAD_TICKS}" if world_k >= 0
                   else f"tick {b.k} after the mission's last ({self.last_tick})")
        else:
            bad = self._position(b.px, b.py, t)
        last = self.last_beacon.get(b.id)
        if bad is None and last is not None:
            jump, elapsed = math.hypot(b.px - last[1], b.py - last[2]), self._elapsed(t, world_k, last)
            if jump > self.reach_m(elapsed):
                bad = f"moved {jump:.6g} m in {elapsed:.6g} s"
        if bad is not None:
            return Intrusion(IntrusionKind.POSITION, source, key, bad)
        who = self._agent(b.id, source, key, now)
        if who is None:
            self.last_beacon[b.id] = (t if last is None else max(t, last[0]), b.px, b.py, world_k)
        return who

    def check_cmd(self, c: wire.Cmd, source: str, key: str, now: float, world_k: int,
                  ticked: bool = True) -> Intrusion | None:
        """A command as the world receives it; world_k: the newest tick it has published. ticked: the command
        names its tick (the project's own; a ROS 2 cmd_vel does not), and an agent has one command a tick: a
        different one for a tick already commanded is a conflict (whoever sent it: the world cannot tell
        which of two sessions stamped with the agent's id is the agent, but the record must say)."""
        l_m = self.head_offset.get(c.id, 0.0)
        if ticked:  # the project's command: u = M(θ) [v, ω], held over the step
            u = math.hypot(c.v_mps, l_m * c.omega_radps)
        else:  # a robot base holds the twist itself: the head point's speed over the step's arc (agent/ros2_io.py)
            u = self._arc_speed(c.v_mps, c.omega_radps, l_m, self.s.meta.dt_s)
            if not abs(c.omega_radps) * self.s.meta.dt_s <= math.pi * (1.0 + COMMAND_TOL):
                return Intrusion(IntrusionKind.COMMAND, source, key, f"ω = {c.omega_radps:.6g} rad/s turns more than "
                                 f"half a turn in a step")
        if not u <= self.u_max * (1.0 + COMMAND_TOL):
            return Intrusion(IntrusionKind.COMMAND, source, key, f"|u| = {u:.6g} m/s above the bound {self.u_max:.6g}")
        if c.k > world_k:
            return Intrusion(IntrusionKind.COMMAND, source, key, f"command for tick {c.k}, newest tick is {world_k}")
        who = self._agent(c.id, source, key, now)
        if who is not None or not ticked:
            return who
        had = self.cmds.setdefault((c.id, c.k), (c.v_mps, c.omega_radps))
        if had != (c.v_mps, c.omega_radps):
            return Intrusion(IntrusionKind.CONFLICT, source, key, f"agent {c.id} tick {c.k}: ({c.v_mps:.6g}, "
                             f"{c.omega_radps:.6g}) after ({had[0]:.6g}, {had[1]:.6g})")
        if len(self.cmds) > 64 * len(self.radius):  # only recent ticks matter: forget the older half
            for ck in [ck for ck in self.cmds if ck[1] < world_k - 32]:
                del self.cmds[ck]
        return None

    def check_odometry(self, st: wire.State, source: str, key: str, world_k: int = -1) -> Intrusion | None:
        """A robot's odometry (ROS 2 mode) as its agent receives it: the plant's (the world's session, as a
        state), a pose the robot can have reached, and within reach of the last admitted one; its time taken
        no later than trusted time (world_k: the receiver's newest clock, -1: none)."""
        bad = self.check_world_source(source, key)
        if bad is not None:
            return bad
        t = min(st.t, self.trusted_t(world_k))
        where = self._position(st.x, st.y, t)
        last = self.last_odom.get(st.id)
        if where is None and last is not None:
            jump, elapsed = math.hypot(st.x - last[1], st.y - last[2]), self._elapsed(t, world_k, last)
            if not jump <= self.reach_m(elapsed):
                where = f"odometry moved {jump:.6g} m in {elapsed:.6g} s"
        if where is not None:
            return Intrusion(IntrusionKind.POSITION, source, key, where)
        self.last_odom[st.id] = (t if last is None else max(t, last[0]), st.x, st.y, world_k)
        return None

    def check_set_size(self, n_bytes: int, source: str, key: str) -> Intrusion | None:
        """Before decoding an obstacle set: no larger than the run's largest (decoding 4,000 ids ten times a
        second starves an agent)."""
        if n_bytes > self.max_set_bytes:
            return Intrusion(IntrusionKind.OVERSIZE, source, key,
                             f"an obstacle set of {n_bytes} bytes, the run's largest is {self.max_set_bytes}")
        return None

    def check_obstacles(self, o: wire.ObstacleSet, source: str, key: str) -> Intrusion | None:
        """An obstacle set: its content alone decides (a truthful set does no harm whoever sends it)."""
        if o.id not in self.radius:
            return Intrusion(IntrusionKind.UNKNOWN_AGENT, source, key, f"agent {o.id} is not in the scenario")
        unknown = [oid for oid in o.obstacles if oid not in self.polygons]
        if unknown:
            return Intrusion(IntrusionKind.UNKNOWN_OBSTACLE, source, key,
                             f"{len(unknown)} obstacle id(s) not in the scenario, e.g. {unknown[0][:40]!r}")
        for oid, hull in o.obstacles.items():
            bad = self.hull_problem(oid, hull)
            if bad is not None:
                return Intrusion(IntrusionKind.HULL, source, key, f"obstacle {oid!r}: {bad}")
        return None

    def hull_problem(self, oid: str, hull: tuple[tuple[float, float], ...]) -> str | None:
        return self.hulls.problem(oid, hull)

    @property
    def hulls_ok(self) -> set[tuple[str, tuple[tuple[float, float], ...]]]:
        """The hulls found on their obstacle's boundary and remembered (HullChecks)."""
        return self.hulls.ok

    def check_report(self, agent_id: int | None, source: str, key: str, now: float) -> Intrusion | None:
        """A report (reconswarm/net/wire/report.py): an agent's like its other messages (a known agent, from its
        pinned session); the world's only from the world's session."""
        if agent_id is not None:
            return self._agent(agent_id, source, key, now)
        if source != self.pins.world:
            return Intrusion(IntrusionKind.IMPERSONATION, source, key,
                             f"simworld speaks from session {self.pins.world or '(none yet)'}")
        return None

    # -- the world's messages -------------------------------------------------------------------------

    def check_world_source(self, source: str, key: str) -> Intrusion | None:
        """Clock, state, scan, truth: only from the world's session, pinned at the first of them."""
        if self.pins.world is None and source != UNATTRIBUTED:
            self.pins.world = source
        if source != self.pins.world:
            return Intrusion(IntrusionKind.NOT_FROM_WORLD, source, key,
                             f"the world speaks from session {self.pins.world or '(none yet)'}")
        return None

    def check_clock(self, c: wire.Clock, source: str, key: str) -> Intrusion | None:
        bad = self.check_world_source(source, key)
        if bad is not None:
            if c.end:
                return Intrusion(bad.kind, source, key, f"{bad.detail} (this one claims the end: {c.reason!r})")
            return bad
        dt = self.s.meta.dt_s
        if c.k > self.last_tick:  # (the world ends the mission at its duration: a later tick is not its clock)
            return Intrusion(IntrusionKind.CLOCK, source, key,
                             f"tick {c.k} after the mission's last ({self.last_tick})")
        if abs(c.t - c.k * dt) > 1e-9 * max(1.0, abs(c.t)):
            return Intrusion(IntrusionKind.CLOCK, source, key, f"t = {c.t:.9g} s at tick {c.k} (dt {dt} s)")
        if self.clock_mode is not None and self.clock_mode != (c.mode, c.speed):
            return Intrusion(IntrusionKind.CLOCK, source, key,
                             f"mode {c.mode} x{c.speed:g}, the run's is {self.clock_mode[0]} x{self.clock_mode[1]:g}")
        self.clock_mode = (c.mode, c.speed)
        return None
