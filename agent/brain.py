"""One agent's planning state and its tick, with no transport: what an agent process runs.

It calls the same pure functions as the in-process engine (reconswarm.paper: planner, knowledge, deadlock,
leader) with N = 1 and its neighbours, in the engine's order, so a lockstep run
reproduces `reconswarm sim` (see reconswarm_bringup/engine.py for the tick order).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from reconswarm.geometry.plane import Edges, norm2
from reconswarm.paper.blocked import Group, inside, lost_groups, merged_hulls, pass_gap_m
from reconswarm.paper.deadlock import StackedStalls, StallState, generator, window_ticks
from reconswarm.paper.knowledge import KnownObstacles, obstacle_view
from reconswarm.paper.leader import VirtualLeader
from reconswarm.paper.planner import Neighbours, ObstacleView
from reconswarm.planners import registry
from reconswarm.planners.seam import Tick
from reconswarm.plant.unicycle import inputs
from reconswarm.scenario.model import PlannerKind, Scenario

Array = NDArray[np.float64]


class Located(Protocol):
    """Anything with a head point: a Peer, a beacon."""

    @property
    def px(self) -> float: ...
    @property
    def py(self) -> float: ...


class Body(Located, Protocol):
    """Another agent's robot as a tick plans with it: a Peer, or the beacon it announced."""

    @property
    def id(self) -> int: ...
    @property
    def radius(self) -> float: ...


class Peer(NamedTuple):
    """What an agent knows of another: its last announced head point and radius (a tuple: dozens are made per
    agent and tick)."""

    id: int
    px: float
    py: float
    radius: float


class Plan(NamedTuple):
    """One agent's tick k, ready for the law (AgentBrain.plan): rows (1, ...) of the planner's batched inputs."""

    brain: AgentBrain
    k: int
    pos: Array  # (1, 2) head point at k
    center: Array  # (1, 2) the target's centre, or this agent's copy of the virtual leader
    lead_vel: Array | None  # (1, 2) the leader's velocity (virtual leader), else None
    nb: Neighbours  # (1, K) peers within d_max,ij, in increasing id
    ob: ObstacleView  # (1, M) known hulls
    grew: bool  # the obstacle set grew at k
    theta: float  # heading at k (radians): the command goes out as the unicycle's (v, ω) there
    heard: Neighbours | None = None  # peers within link range (planners that need hulls)
    hulls: list[Array] | None = None  # the known hulls, in obstacle-id order (planners that need hulls)


class AgentBrain:
    def __init__(self, s: Scenario, agent_id: int) -> None:
        self.s = s
        self.cfg = s.planner
        self.id = agent_id
        idx = s.agent_index(agent_id)
        spec = s.agents[idx]
        self.r = np.array([spec.radius_m])
        self.l = np.array([s.head_offsets[idx]], dtype=np.float64)  # head offset (1,)
        self.offset = np.array([spec.offset_m], dtype=np.float64)
        self.target = np.asarray(s.target_m, dtype=np.float64)
        self.known = KnownObstacles()
        self.rev = 0  # revision of self.known, bumped when it grows
        self.union = KnownObstacles()  # virtual leader: everything the swarm knew at the previous tick
        self._union_rev = 0  # own revision last merged into the union
        self._edges: Edges | None = None  # edges of the known hulls, in obstacle-id order
        self._edges_rev = 0
        self._centres = np.zeros((0, 2))
        self._reach = np.zeros(0)
        self._blocked_key: tuple[int, tuple[tuple[int, float, float, float], ...]] = (-1, ())
        self._groups: tuple[list[Array], Array, list[Group]] = ([], np.zeros((0, 3)), [])  # (hulls, discs, groups)
        # (the hulls with lost robots, the rest), by the groups left apart (those holding our head point)
        self._blocked: dict[tuple[int, ...], tuple[Edges | None, list[Body]]] = {}
        self._seen: set[tuple[float, float]] = set()  # contour points already merged (merging again is a no-op)
        w = window_ticks(self.cfg.stall_window_s, s.meta.dt_s)
        self.stall = StallState.create(1, w, [generator(s.meta.seed, agent_id)])
        self.leader = VirtualLeader(s) if self.cfg.kind == PlannerKind.VIRTUAL_LEADER else None
        self.planner = registry.make(s, [agent_id])

    def inputs(self, u: Array, theta: float) -> tuple[float, float]:
        """The command u (2,) as the unicycle's own inputs (v, ω) at heading θ: eq. 3 inverted
        (reconswarm.plant.unicycle.inputs, which the in-process engine applies to everyone at once)."""
        v, w = inputs(u[None, :], np.array([theta]), self.l)
        return float(v[0]), float(w[0])

    def linked(self, p: Array, peers: Sequence[Body]) -> list[int]:
        """Ids of peers within link range of head point p (2,): whose obstacle sets we merge."""
        return self.linked_at(p, {x.id: x for x in peers})

    def linked_at(self, p: Array, at: Mapping[int, Located]) -> list[int]:
        """Those of the peers in `at` (id -> its head point) within link range of p (2,), in the order of `at`.
        One peer at a time (a handful, where numpy's cost per call dominates): the same IEEE operations as
        norm2 and reconswarm.paper.link.linked, so the same answer to the last bit."""
        px, py, link_m, out = float(p[0]), float(p[1]), self.cfg.link_range_m, []
        for a, b in at.items():
            dx, dy = px - b.px, py - b.py
            if math.sqrt(dx * dx + dy * dy) <= link_m:
                out.append(a)
        return out

    def tick(self, k: int, p: Array, scan: Mapping[str, Array | Sequence[tuple[float, float]]], peers: Sequence[Body],
             shared: list[dict[str, Array]], swarm_sets: list[dict[str, Array]] | None = None,
             lost: Sequence[Body] = ()) -> tuple[Array, bool]:
        """Plan tick k: `plan`, then the law for this agent alone. Returns (u (2,), whether the obstacle set grew)."""
        plan = self.plan(k, p, scan, peers, shared, swarm_sets, lost)
        return law([plan])[0], plan.grew

    def plan(self, k: int, p: Array, scan: Mapping[str, Array | Sequence[tuple[float, float]]], peers: Sequence[Body],
             shared: list[dict[str, Array]], swarm_sets: list[dict[str, Array]] | None = None,
             lost: Sequence[Body] = (), theta: float = 0.0) -> Plan:
        """Everything tick k's law needs, knowledge merged: `law` turns plans into commands, one or many at once.

        p (2,) own head point at k; scan: obstacle id -> contour points sensed at k ((P, 2), or (x, y) pairs);
        peers: every other agent's last announcement (at k when fresh); shared: the obstacle sets at k-1 of
        the peers within link range; swarm_sets (virtual leader only): every agent's set at k-1, own excluded;
        lost: where the robots of peers whose agents are gone stand (still, for good); theta: heading at k.
        """
        pos = p.reshape(1, 2)
        if self.leader is not None:
            for sets in swarm_sets or []:
                self.union.merge_all(sets)
            if self._union_rev != self.rev:
                self.union.merge_all(self.known.hulls)
                self._union_rev = self.rev
            center, lead_vel = self.leader.step(k, [h for _, h in self.union.sorted_items()])
        else:
            center, lead_vel = self.target.reshape(1, 2), None
        grew = self.known.merge_all(self._new_points(scan))
        for sets in shared:
            grew |= self.known.merge_all(sets)
        if grew:
            self.rev += 1
        if not self.planner.needs_tables:
            nb, ob = Neighbours.empty(1), ObstacleView.empty(1)
        elif lost:  # robots whose agents are gone: obstacles where they block a passage (reconswarm.paper.blocked)
            ob, alone = self._obstacles_with_lost(pos, lost)
            nb = self._neighbours(pos, [*peers, *alone])
        else:
            nb = self._neighbours(pos, peers)
            ob = self._obstacles(pos)
        plan = Plan(self, k, pos, center.reshape(1, 2), lead_vel, nb, ob, grew, theta)
        if self.planner.needs_hulls:  # the lost robots as peers standing still
            heard = self._heard(pos, [*peers, *lost])
            plan = plan._replace(heard=heard, hulls=[h for _, h in self.known.sorted_items()])
        return plan

    def _heard(self, pos: Array, peers: Sequence[Body]) -> Neighbours:
        """Peers within link range, in increasing id (the engine's pairs within link range)."""
        by_id = {x.id: x for x in sorted(peers, key=lambda x: x.id)}
        near = [by_id[a] for a in self.linked_at(pos[0], by_id)]
        if not near:
            return Neighbours.empty(1)
        q = np.array([[x.px, x.py] for x in near], dtype=np.float64)
        rr = np.array([x.radius for x in near], dtype=np.float64)
        return Neighbours(q.reshape(1, -1, 2), rr.reshape(1, -1), np.ones((1, q.shape[0]), dtype=bool))

    def _neighbours(self, pos: Array, peers: Sequence[Body]) -> Neighbours:
        """Peers within d_max,ij, in increasing id (entries beyond it would add exact zeros)."""
        # One peer at a time (a handful): the same IEEE operations as norm2(pos - q) <= r + r_j + d_max over arrays.
        px, py, r, d_max = float(pos[0, 0]), float(pos[0, 1]), float(self.r[0]), self.cfg.d_max_m
        near = []
        for x in sorted(peers, key=lambda x: x.id):
            dx, dy = px - x.px, py - x.py
            if math.sqrt(dx * dx + dy * dy) <= r + x.radius + d_max:
                near.append(x)
        if not near:
            return Neighbours.empty(1)
        q = np.array([[x.px, x.py] for x in near], dtype=np.float64)
        rr = np.array([x.radius for x in near], dtype=np.float64)
        return Neighbours(q.reshape(1, -1, 2), rr.reshape(1, -1), np.ones((1, q.shape[0]), dtype=bool))

    def _obstacles(self, pos: Array) -> ObstacleView:
        """Distances to the known hulls; none at all when every hull is beyond repulsion reach (their terms
        would be exact zeros), which a bounding circle per hull tells cheaply."""
        if self._edges_rev != self.rev:  # the hulls' edges change only when the set grows
            hulls = [h for _, h in self.known.sorted_items()]
            self._edges = Edges.of(hulls) if hulls else None
            self._centres = np.array([h.mean(axis=0) for h in hulls]).reshape(-1, 2)
            self._reach = np.array([float(norm2(h - h.mean(axis=0)).max()) for h in hulls])
            self._edges_rev = self.rev
        if self._edges is None:
            return ObstacleView.empty(1)
        bound = norm2(pos - self._centres) - self._reach  # <= the distance to each hull
        if not (bound <= self.r[0] + self.cfg.d_max_m).any():
            return ObstacleView.empty(1)
        m = self._edges.ax.shape[0]
        return obstacle_view(pos, 1, m, np.zeros(m, dtype=np.int64), np.arange(m), self._edges)

    def _obstacles_with_lost(self, pos: Array, lost: Sequence[Body]) -> tuple[ObstacleView, list[Body]]:
        """The known hulls with each lost robot that blocks a passage merged into one convex obstacle with
        what it blocks, unless that obstacle holds our head point (`merged_hulls`); the lost robots left
        to be avoided as neighbours."""
        key = (self.rev, tuple(sorted((b.id, b.px, b.py, b.radius) for b in lost)))
        if key != self._blocked_key:  # (lost robots stand still: this changes when they or the hulls do)
            discs = np.array([[b.px, b.py, b.radius] for b in lost], dtype=np.float64)
            known = [h for _, h in self.known.sorted_items()]
            groups = lost_groups(known, discs, pass_gap_m(float(self.r[0]), self.cfg.d_max_m))
            self._blocked_key, self._groups, self._blocked = key, (known, discs, groups), {}
        known, discs, groups = self._groups
        apart = inside(groups, pos[0]) if groups else ()
        if (got := self._blocked.get(apart)) is None:
            hulls, absorbed = merged_hulls(known, discs.shape[0], groups, apart)
            alone = [b for b, a in zip(lost, absorbed.tolist(), strict=True) if not a]
            got = self._blocked[apart] = (Edges.of(hulls) if hulls else None, alone)
        edges, alone = got
        if edges is None:
            return ObstacleView.empty(1), alone
        m = edges.ax.shape[0]
        return obstacle_view(pos, 1, m, np.zeros(m, dtype=np.int64), np.arange(m), edges), alone

    def _new_points(self, scan: Mapping[str, Array | Sequence[tuple[float, float]]]) -> dict[str, Array]:
        """The scanned points not merged before (merging a point again is a no-op), by obstacle."""
        out = {}
        for oid, pts in scan.items():
            fresh = [xy for xy in map(tuple, pts.tolist() if isinstance(pts, np.ndarray) else pts)
                     if xy not in self._seen]
            if fresh:
                self._seen.update(fresh)
                out[oid] = np.array(fresh, dtype=np.float64)
        return out

    def obstacle_sets(self) -> dict[str, Array]:
        return dict(self.known.hulls)


_STALLS = StackedStalls()  # the stall rows of `law`'s last batch (a process's host computes the same agents each tick)


def law(plans: Sequence[Plan]) -> Array:
    """The planner's commands u (P, 2) for several agents' ticks at once, row by row.

    The paper's law (reconswarm.planners.paper_law) takes the rows batched: its inputs stacked (neighbour and
    obstacle tables padded with invalid columns, which add nothing), each agent's stall history its own row, so
    every row is the same bit for bit as one agent's alone (reconswarm/paper/planner.py sums column by column
    from zero; the in-process engine computes everyone this way). A planner with state per agent (navground's)
    is asked by each agent's own planner, one row each. The agents must share one scenario (a host's do) and tick k."""
    one, n = plans[0], len(plans)
    if not one.brain.planner.needs_tables:
        return np.concatenate([x.brain.planner.command(_tick(x, x.pos, x.brain.r, x.brain.offset, x.center,
                                                             x.lead_vel, x.brain.stall)) for x in plans])
    if n == 1:  # (one agent: its own arrays)
        return one.brain.planner.command(_tick(one, one.pos, one.brain.r, one.brain.offset, one.center,
                                               one.lead_vel, one.brain.stall))
    pos = np.concatenate([x.pos for x in plans])  # (P, 2)
    r = np.concatenate([x.brain.r for x in plans])  # (P,)
    offset = np.concatenate([x.brain.offset for x in plans])  # (P, 2)
    center = np.concatenate([x.center for x in plans])  # (P, 2)
    lead = None if one.lead_vel is None else np.concatenate([x.lead_vel for x in plans if x.lead_vel is not None])
    st = _STALLS.take([x.brain.stall for x in plans])
    t = _tick(one, pos, r, offset, center, lead, st)
    t.nb, t.ob = Neighbours.stack([x.nb for x in plans]), ObstacleView.stack([x.ob for x in plans])
    u = one.brain.planner.command(t)
    _STALLS.give_back(st, [x.brain.stall for x in plans])
    return u


def _tick(plan: Plan, pos: Array, r: Array, offset: Array, center: Array, lead: Array | None,
          stall: StallState) -> Tick:
    """The seam's tick for rows (one plan's own, or several stacked): tables from the plan when there is one row."""
    b = plan.brain
    if plan.brain.planner.needs_tables:
        return Tick(plan.k, b.s.meta.dt_s, pos, np.array([plan.theta]), r, center, offset, lead, stall,
                    nb=plan.nb, ob=plan.ob)
    return Tick(plan.k, b.s.meta.dt_s, pos, np.array([plan.theta]), r, center, offset, lead, stall,
                heard=plan.heard, hulls=[plan.hulls or []])


def commands(plans: Sequence[Plan]) -> list[tuple[float, float]]:
    """`law`'s commands as each unicycle's own inputs (v, ω) at its heading: eq. 3 inverted for all rows at once
    (reconswarm.plant.unicycle.inputs, element by element: each row the same as `AgentBrain.inputs` alone)."""
    u = law(plans)  # (P, 2)
    theta = np.array([x.theta for x in plans], dtype=np.float64)  # (P,)
    l_m = plans[0].brain.l if len(plans) == 1 else np.concatenate([x.brain.l for x in plans])  # (P,)
    v, w = inputs(u, theta, l_m)
    return list(zip(v.tolist(), w.tolist(), strict=True))
