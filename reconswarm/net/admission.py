"""Admission: can a well-formed message belong to this run? Pure rules, no zenoh.

The wire decoders (wire.py) refuse what is malformed. This module refuses what is well formed but that the
run cannot contain, from what the scenario says and what has been seen; each refusal is an `Intrusion`,
which the receiver drops, counts (`IntrusionTally`) and logs. The rules:

- agents: only the scenario's ids; a beacon's radius is the scenario's radius for that id; a position lies
  inside the scenario's extent grown by what the fastest possible motion covers by then, and within the
  same bound of that agent's previous beacon (`reach_m`);
- obstacle sets: only the scenario's obstacle ids (so never more ids than it has); a hull has at most as
  many vertices as the sensor samples on that obstacle, and every vertex lies on the true obstacle's
  boundary within `HULL_TOL_M`: agents only share hulls of sensed contour points, which lie on the true
  boundary, so a shared hull is never larger than the real obstacle whoever sent it;
- commands: |u| at most `command_bound_mps` (what the planner can output with bounded repulsion) and for a
  tick the world has published;
- the world's messages (clock, state, scan, truth): only from the world's session, pinned at its first
  clock; the clock keeps its mode and speed, and t = k dt;
- an agent's messages (beacon, cmd): only from the session that agent speaks from (`Pins`, pinned at first
  sight; another session may take over only once the pinned one has been silent `repin_after_s`, as a
  restarted agent's new session does);
- membership (`Membership`): an agent is alive while its liveliness token is there AND its own session's
  data keeps coming; a token anyone can declare decides nothing alone.

Sources are the publishers' zenoh session ids as their samples carry them: the id in the sample's
timestamp (`session.sample_source`), which every session of the run stamps (timestamping is on in all of
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

from reconswarm.geometry import Edges, sample_boundary, signed_distance
from reconswarm.net import wire
from reconswarm.paper.planner import max_repulsion_speed
from reconswarm.scenario import Scenario
from reconswarm.sim.sensing import SAMPLE_SPACING_M

HULL_TOL_M = 1e-3  # a shared vertex must lie within this of the true boundary (float error is ~1e-12 m)
RADIUS_RTOL = 1e-9
POSITION_MARGIN_M = 1.0
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

    repin_after_s: float = 1.0
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


class Admission:
    """The rules above for one scenario; `check_*` return None (admitted) or the Intrusion."""

    def __init__(self, s: Scenario, pins: Pins | None = None, hull_vertices_kept: int = HULL_VERTICES_KEPT) -> None:
        self.s = s
        self.pins = pins or Pins()
        self.radius = {a.id: a.radius_m for a in s.agents}
        self.head_offset = {a.id: float(s.head_offsets[i]) for i, a in enumerate(s.agents)}
        self.polygons = {o.id: s.polygon(k) for k, o in enumerate(s.obstacles)}
        self.edges = {o: Edges.of([poly]) for o, poly in self.polygons.items()}
        # Hulls already found on their obstacle's boundary: peers share the same merged hulls over and over,
        # and the check depends on the hull alone (a refused hull is never kept; the memory is bounded).
        self.hulls_ok: set[tuple[str, tuple[tuple[float, float], ...]]] = set()
        self._kept_vertices, self._keep_vertices = 0, hull_vertices_kept
        self.max_vertices = {o: int(sample_boundary(poly, SAMPLE_SPACING_M).shape[0])
                             for o, poly in self.polygons.items()}
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
        self.last_beacon: dict[int, tuple[float, float, float]] = {}  # id -> (t, px, py)

    # -- helpers -------------------------------------------------------------------------------------

    def reach_m(self, dt_s: float) -> float:
        """How far a head point can move in dt_s of simulated time (|ṗ| = |u| for the unicycle's head)."""
        return self.u_max * max(0.0, dt_s) + POSITION_MARGIN_M

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

    def check_beacon(self, b: wire.Beacon, source: str, key: str, now: float) -> Intrusion | None:
        if b.id not in self.radius:
            return Intrusion(IntrusionKind.UNKNOWN_AGENT, source, key, f"agent {b.id} is not in the scenario")
        want = self.radius[b.id]
        if abs(b.radius - want) > RADIUS_RTOL * max(1.0, want):
            return Intrusion(IntrusionKind.RADIUS, source, key, f"radius {b.radius:.6g} m, the scenario's is {want} m")
        bad = self._position(b.px, b.py, b.t)
        if bad is None and b.id in self.last_beacon:
            t0, x0, y0 = self.last_beacon[b.id]
            jump = math.hypot(b.px - x0, b.py - y0)
            if jump > self.reach_m(abs(b.t - t0)):
                bad = f"moved {jump:.6g} m in {abs(b.t - t0):.6g} s"
        if bad is not None:
            return Intrusion(IntrusionKind.POSITION, source, key, bad)
        who = self._agent(b.id, source, key, now)
        if who is None:
            self.last_beacon[b.id] = (b.t, b.px, b.py)
        return who

    def check_cmd(self, c: wire.Cmd, source: str, key: str, now: float, world_k: int) -> Intrusion | None:
        """A command as the world receives it; world_k: the newest tick it has published."""
        u = math.hypot(c.v_mps, self.head_offset.get(c.id, 0.0) * c.omega_radps)  # |u| = |M(θ) [v, ω]|
        if u > self.u_max * (1.0 + COMMAND_TOL):
            return Intrusion(IntrusionKind.COMMAND, source, key, f"|u| = {u:.6g} m/s above the bound {self.u_max:.6g}")
        if c.k > world_k:
            return Intrusion(IntrusionKind.COMMAND, source, key, f"command for tick {c.k}, newest tick is {world_k}")
        return self._agent(c.id, source, key, now)

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
        if len(hull) > self.max_vertices[oid]:
            return f"{len(hull)} vertices, at most {self.max_vertices[oid]} can be sensed"
        if not hull or (oid, hull) in self.hulls_ok:
            return None
        pts = np.asarray(hull, dtype=np.float64).reshape(-1, 2)
        d = signed_distance(pts[:, 0:1], pts[:, 1:2], self.edges[oid], normals=False)  # (P, 1)
        worst = float(np.abs(d).max())
        if not worst <= HULL_TOL_M:
            return f"a vertex {worst:.6g} m off the obstacle's boundary"
        if self._kept_vertices + len(hull) > self._keep_vertices:
            self.hulls_ok.clear()
            self._kept_vertices = 0
        self.hulls_ok.add((oid, hull))
        self._kept_vertices += len(hull)
        return None

    def check_report(self, agent_id: int | None, source: str, key: str, now: float) -> Intrusion | None:
        """A report (reconswarm/net/report.py): an agent's like its other messages (a known agent, from its
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
        if abs(c.t - c.k * dt) > 1e-9 * max(1.0, abs(c.t)):
            return Intrusion(IntrusionKind.CLOCK, source, key, f"t = {c.t:.9g} s at tick {c.k} (dt {dt} s)")
        if self.clock_mode is not None and self.clock_mode != (c.mode, c.speed):
            return Intrusion(IntrusionKind.CLOCK, source, key,
                             f"mode {c.mode} x{c.speed:g}, the run's is {self.clock_mode[0]} x{self.clock_mode[1]:g}")
        self.clock_mode = (c.mode, c.speed)
        return None


@dataclass
class Membership:
    """Who is alive: a liveliness token AND that agent's own data (beacons or commands) still coming.

    Before `start`, a token alone counts (nobody sends data before the first tick). Afterwards an agent
    with a token counts until it has been silent both `fresh_s` of wall time and `fresh_sim_s` of
    simulated time (so neither a stalled world, during which nobody sends, nor a fast realtime clock makes
    a live agent look dead); an agent not heard since its token appeared (or since the start) gets
    `grace_s` / `grace_sim_s` likewise. A token that goes counts as gone `confirm_s` later (unless it is
    back by then); after the caller itself stalled (`settle`), a token that goes is kept for a while; while
    the caller's own session has no router (`link`), nobody is judged: every token goes at once then, and
    nobody's data can come. Times: `wall` (the caller's monotonic seconds), `sim` (the newest simulated
    time it knows).
    """

    fresh_s: float = 2.0
    fresh_sim_s: float = 2.0
    grace_s: float = 10.0
    grace_sim_s: float = 5.0
    started: tuple[float, float] | None = None
    tokens: dict[int, tuple[float, float]] = field(default_factory=dict)  # id -> (wall, sim) it appeared
    heard: dict[int, tuple[float, float]] = field(default_factory=dict)  # id -> (wall, sim) of its last data
    # A token that goes is gone this long later, unless it came back: a router that dies takes every token
    # with it a moment before the caller's session finds its own link gone (measured: the deletions come
    # first, with the router still listed, in 1 of 5 trials), so `link(False)` still comes in time.
    confirm_s: float = 0.0
    settle_until: float = -math.inf  # wall: a token that goes before then is kept (see settle)
    going: dict[int, float] = field(default_factory=dict)  # tokens that went, not yet judged: id -> wall it went
    unlinked: bool = False  # the caller's own session has no router (see link)

    def start(self, wall: float, sim: float) -> None:
        if self.started is None:
            self.started = (wall, sim)

    def settle(self, until_wall: float) -> None:
        """The caller itself did not run for a while (SIGSTOP, a starved machine): its session may have lapsed,
        and every token it hears may go and come back within a moment. Until `until_wall` a token that goes
        is kept (a list of the living that is suddenly empty broke lockstep's determinism); it is let go
        then, if it has not come back."""
        self.settle_until = until_wall

    def link(self, up: bool, wall: float, sim: float, settle_s: float) -> None:
        """The caller's own session lost its router (up=False: a router that died or froze takes every token
        with it, and nobody's data can reach us) or has one again (up=True, also when it is a new router).
        While it has none nobody is judged; once back, tokens that went have `settle_s` to come back, and
        everyone's data is awaited afresh (the grace, as after the start)."""
        self.unlinked = not up
        if up:
            self.settle_until = max(self.settle_until, wall + settle_s)
            if self.started is not None:
                self.started = (wall, sim)
                self.heard.clear()

    def token(self, agent_id: int, present: bool, wall: float, sim: float) -> None:
        if present:
            self.going.pop(agent_id, None)
            self.tokens.setdefault(agent_id, (wall, sim))
        elif agent_id in self.tokens:
            self.going.setdefault(agent_id, wall)
            self._judge(wall)

    def _judge(self, wall: float) -> None:
        """Tokens that went: gone once confirmed and settled, unless the caller has no router."""
        if self.unlinked:
            return
        for a, went in list(self.going.items()):
            if wall >= max(went + self.confirm_s, self.settle_until):
                self.tokens.pop(a, None)
                del self.going[a]

    def data(self, agent_id: int, wall: float, sim: float) -> None:
        self.heard[agent_id] = (wall, sim)

    def alive(self, agent_id: int, wall: float, sim: float) -> bool:
        if self.going:
            self._judge(wall)
        since = self.tokens.get(agent_id)
        if since is None:
            return False
        if self.started is None or self.unlinked:
            return True
        last = self.heard.get(agent_id)
        if last is not None and last[0] >= since[0]:
            return wall - last[0] <= self.fresh_s or sim - last[1] <= self.fresh_sim_s
        ref = (max(since[0], self.started[0]), max(since[1], self.started[1]))
        return wall - ref[0] <= self.grace_s or sim - ref[1] <= self.grace_sim_s

    def alive_ids(self, wall: float, sim: float) -> list[int]:
        self._judge(wall)
        return sorted(a for a in list(self.tokens) if self.alive(a, wall, sim))


@dataclass
class IntrusionTally:
    """Counts per (kind, source), with the first time each was seen; `add` says whether to log it."""

    rows: dict[tuple[str, str], list[float]] = field(default_factory=dict)  # -> [count, first_t]
    max_rows: int = 256

    def add(self, i: Intrusion, t: float) -> bool:
        k = (i.kind.value, i.source)
        row = self.rows.get(k)
        if row is None:
            if len(self.rows) >= self.max_rows:  # an attacker cycling session ids: fold the rest into one row
                k = (i.kind.value, "(other sources)")
                row = self.rows.setdefault(k, [0, t])
            else:
                row = self.rows[k] = [0, t]
        row[0] += 1
        return row[0] == 1

    @property
    def total(self) -> int:
        return int(sum(r[0] for r in self.rows.values()))

    def as_rows(self) -> list[tuple[str, str, int, float]]:
        """(kind, source, count, first_t), as the run record stores them."""
        return [(k, s, int(r[0]), float(r[1])) for (k, s), r in sorted(self.rows.items())]
