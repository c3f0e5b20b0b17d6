"""The run as Foxglove messages: pure functions from one instant of the swarm to `foxglove.messages`, and
`SceneChannels`, which logs them on the channels below of a foxglove Context.

Used by `monitor export --format mcap` on a recorded run (an MCAP writer on the Context) and meant for the
monitor process to serve the same channels live (the SDK's WebSocket server on the same Context; both
sinks can share it). No file, no clock, no zenoh here: the caller gives the times (integer ns since the
epoch).

Channels (topic, schema):
- `/world` `foxglove.SceneUpdate`: the true obstacles (filled polygons), the target slots p* + Δ_i
  (spheres), the attraction disk B(p*, R_c); the same every time (logged once per simulated second so
  that a player that seeks, or a late viewer, has it).
- `/swarm` `foxglove.SceneUpdate`: every agent as a disc of its radius at its head point p_i with a
  heading arrow and its id, coloured by its group (connected component of the swarm graph; grey when
  the agent is not alive), and the graph's links as lines; each update replaces the previous one.
- `/tracking_error` JSON: `{"t_s", "max_m", "agent_<id>": ‖p_i - (p* + Δ_i)‖ ...}`, one field per agent
  (Plot panel: `/tracking_error.agent_3`).
- `/metrics` JSON: the run record's per-tick safety fields and the number of groups.
- `/events` `foxglove.Log`: split, merge, agent_lost, agent_joined, with the groups before and after.

Frame `world`, z up; the plane of the mission is z = 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from typing import Any

import foxglove
import numpy as np
from foxglove.channels import LogChannel, SceneUpdateChannel
from foxglove.messages import (
    ArrowPrimitive,
    Color,
    CylinderPrimitive,
    LinePrimitive,
    LinePrimitiveLineType,
    Log,
    LogLevel,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneEntityDeletion,
    SceneEntityDeletionType,
    SceneUpdate,
    SpherePrimitive,
    TextPrimitive,
    Timestamp,
    TriangleListPrimitive,
    Vector3,
)
from numpy.typing import NDArray

from reconswarm.paper.topology import graph_edges, labels
from reconswarm.scenario.model import Scenario

Array = NDArray[np.float64]

FRAME = "world"
TOPIC_WORLD = "/world"
TOPIC_SWARM = "/swarm"
TOPIC_TRACKING_ERROR = "/tracking_error"
TOPIC_METRICS = "/metrics"
TOPIC_EVENTS = "/events"

# matplotlib's Set1, so that the plot, the animation and the scene colour groups alike.
GROUP_RGB = ((0.894, 0.102, 0.110), (0.216, 0.494, 0.722), (0.302, 0.686, 0.290), (0.596, 0.306, 0.639),
             (1.000, 0.498, 0.000), (1.000, 1.000, 0.200), (0.651, 0.337, 0.157), (0.969, 0.506, 0.749),
             (0.600, 0.600, 0.600))
NOT_ALIVE_RGB = (0.25, 0.25, 0.25)
DISC_HEIGHT_M = 0.4

_IDENTITY = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)


def start_ns(started_unix: str) -> int:
    """The run's wall-clock start (run record meta `started_unix`, seconds as a decimal string) in ns."""
    try:
        return int(Decimal(started_unix) * 1_000_000_000)
    except InvalidOperation:
        raise ValueError(f"started_unix: not a number: {started_unix!r}") from None


def stamp_ns(start: int, t_s: float) -> int:
    """Message time: the run's start (ns since the epoch) plus simulated time t_s."""
    return start + round(t_s * 1e9)


def timestamp(ns: int) -> Timestamp:
    return Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)


def group_index(lab: NDArray[np.int64]) -> NDArray[np.int64]:
    """Group number per agent (0, 1, ... in the order of each group's smallest agent index); -1 if none."""
    out = np.full(lab.shape, -1, dtype=np.int64)
    for n, g in enumerate(sorted(set(lab[lab >= 0].tolist()))):
        out[lab == g] = n
    return out


def _colour(rgb: tuple[float, float, float], a: float = 1.0) -> Color:
    return Color(r=rgb[0], g=rgb[1], b=rgb[2], a=a)


def group_colour(group: int, a: float = 1.0) -> Color:
    return _colour(NOT_ALIVE_RGB if group < 0 else GROUP_RGB[group % len(GROUP_RGB)], a)


@dataclass(frozen=True)
class SwarmFrame:
    """One instant of the swarm, arrays in agent-id order (N agents)."""

    t_s: float
    ids: NDArray[np.int64]  # (N,)
    p: Array  # (N, 2) head points; NaN where unknown (the agent is not drawn)
    theta: Array  # (N,) headings
    alive: NDArray[np.bool_]  # (N,)
    radii: Array  # (N,)
    group: NDArray[np.int64]  # (N,) group number (group_index), -1 when not in a group
    links: NDArray[np.int64]  # (E, 2) agent index pairs of the swarm graph


class SwarmGraph:
    """Follows the swarm graph over consecutive instants (its links have hysteresis, so it needs the
    previous links): feed every recorded tick in order."""

    def __init__(self, link_range_m: float) -> None:
        self.link_range_m = link_range_m
        self.edges = np.zeros((0, 2), dtype=np.int64)

    def step(self, p: Array, alive: NDArray[np.bool_]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """-> (links (E, 2), group number per agent (N,))"""
        active = alive & np.isfinite(p).all(axis=1)
        self.edges = graph_edges(np.nan_to_num(p), active, self.edges, self.link_range_m)
        return self.edges, group_index(labels(p.shape[0], self.edges, active))


def pose(x: float, y: float, z: float = 0.0, yaw: float | None = None) -> Pose:
    """A pose in the scene's frame (yaw None: the identity rotation)."""
    q = _IDENTITY if yaw is None else Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))
    return Pose(position=Vector3(x=x, y=y, z=z), orientation=q)


def agent_entity(aid: int, x: float, y: float, theta: float, radius_m: float, group: int, alive: bool,
                 stamp: Timestamp) -> SceneEntity:
    """A disc of the agent's radius at its head point, a heading arrow and its id."""
    c = group_colour(group if alive else -1, 0.85)
    disc = CylinderPrimitive(pose=pose(x, y, DISC_HEIGHT_M / 2),
                             size=Vector3(x=2 * radius_m, y=2 * radius_m, z=DISC_HEIGHT_M),
                             bottom_scale=1.0, top_scale=1.0, color=c)
    arrow = ArrowPrimitive(pose=pose(x, y, DISC_HEIGHT_M + 0.05, theta), shaft_length=1.4 * radius_m,
                           shaft_diameter=0.25 * radius_m, head_length=0.8 * radius_m,
                           head_diameter=0.7 * radius_m, color=Color(r=0.1, g=0.1, b=0.1, a=1.0))
    label = TextPrimitive(pose=pose(x, y, DISC_HEIGHT_M + 1.0), billboard=True, font_size=14.0,
                          scale_invariant=True, color=Color(r=0.05, g=0.05, b=0.05, a=1.0), text=str(aid))
    return SceneEntity(timestamp=stamp, frame_id=FRAME, id=f"agent/{aid}", cylinders=[disc], arrows=[arrow],
                       texts=[label])


def swarm_update(f: SwarmFrame, ns: int) -> SceneUpdate:
    """The whole swarm at one instant: replaces every entity of the previous update on its topic."""
    stamp = timestamp(ns)
    ents = [agent_entity(int(f.ids[k]), float(f.p[k, 0]), float(f.p[k, 1]), float(f.theta[k]),
                         float(f.radii[k]), int(f.group[k]), bool(f.alive[k]), stamp)
            for k in np.flatnonzero(np.isfinite(f.p).all(axis=1))]
    if f.links.shape[0]:
        pts, cols = [], []
        for i, j in f.links.tolist():
            c = group_colour(int(f.group[i]), 0.8)
            for k in (i, j):
                pts.append(Point3(x=float(f.p[k, 0]), y=float(f.p[k, 1]), z=0.1))
                cols.append(c)
        ents.append(SceneEntity(timestamp=stamp, frame_id=FRAME, id="links", lines=[LinePrimitive(
            type=LinePrimitiveLineType.LineList, pose=pose(0.0, 0.0), thickness=0.4, points=pts, colors=cols)]))
    return SceneUpdate(deletions=[SceneEntityDeletion(timestamp=stamp, type=SceneEntityDeletionType.All)],
                       entities=ents)


def world_update(s: Scenario, ns: int) -> SceneUpdate:
    """The scenario's fixed world: true obstacles, target slots and the attraction disk B(p*, R_c)."""
    stamp = timestamp(ns)
    ents = []
    fill, edge = Color(r=0.6, g=0.6, b=0.6, a=0.9), Color(r=0.25, g=0.25, b=0.25, a=1.0)
    for k, ob in enumerate(s.obstacles):
        poly = s.polygon(k)
        ring = [Point3(x=float(x), y=float(y), z=0.0) for x, y in poly]
        tris = [ring[i] for v in range(1, len(ring) - 1) for i in (0, v, v + 1)]  # a fan: the polygon is convex
        ents.append(SceneEntity(timestamp=stamp, frame_id=FRAME, id=f"obstacle/{ob.id}",
                                triangles=[TriangleListPrimitive(pose=pose(0.0, 0.0), points=tris, color=fill)],
                                lines=[LinePrimitive(type=LinePrimitiveLineType.LineLoop, pose=pose(0.0, 0.0),
                                                     thickness=0.5, points=ring, color=edge)]))
    slots = np.asarray(s.target_m) + s.offsets
    ents.append(SceneEntity(timestamp=stamp, frame_id=FRAME, id="slots", spheres=[
        SpherePrimitive(pose=pose(float(x), float(y)), size=Vector3(x=1.5, y=1.5, z=1.5),
                        color=Color(r=0.0, g=0.0, b=0.0, a=0.8)) for x, y in slots]))
    cx, cy = s.target_m
    r = s.planner.target_radius_m
    circle = [Point3(x=cx + r * math.cos(a), y=cy + r * math.sin(a), z=0.0)
              for a in np.linspace(0.0, 2 * math.pi, 96, endpoint=False)]
    ents.append(SceneEntity(timestamp=stamp, frame_id=FRAME, id="target", lines=[LinePrimitive(
        type=LinePrimitiveLineType.LineLoop, pose=pose(0.0, 0.0), thickness=0.3, points=circle,
        color=Color(r=0.4, g=0.4, b=0.4, a=0.8))]))
    return SceneUpdate(entities=ents)


def tracking_error_schema(ids: NDArray[np.int64]) -> dict[str, Any]:
    """JSON schema of the /tracking_error messages (lets the Plot panel offer every field)."""
    props: dict[str, Any] = {"t_s": {"type": "number"}, "max_m": {"type": "number"}}
    props.update({f"agent_{int(a)}": {"type": "number"} for a in ids})
    return {"type": "object", "title": "reconswarm.TrackingError", "properties": props}


def tracking_errors(t_s: float, ids: NDArray[np.int64], p: Array, slots: Array) -> dict[str, Any]:
    """‖p_i - (p* + Δ_i)‖ of every agent with a known position (others left out), and their maximum."""
    err = np.hypot(p[:, 0] - slots[:, 0], p[:, 1] - slots[:, 1])
    known = np.isfinite(err)
    msg: dict[str, Any] = {"t_s": t_s, "max_m": float(err[known].max()) if known.any() else None}
    msg.update({f"agent_{int(a)}": float(e) for a, e, ok in zip(ids, err, known, strict=True) if ok})
    return msg


METRICS_SCHEMA: dict[str, Any] = {
    "type": "object", "title": "reconswarm.Metrics",
    "properties": {k: {"type": ["number", "null"]} for k in
                   ("t_s", "max_error_m", "min_agent_gap_m", "min_obstacle_gap_m", "groups")}}


def _groups(gs: Any) -> str:
    return " | ".join(",".join(map(str, g)) for g in gs or [])


def event_log(ev: dict[str, Any], ns: int) -> Log:
    """A recorded event (docs/wire.md: t, kind, before, after[, agent, cause]) as a foxglove.Log."""
    kind = str(ev.get("kind", "?"))
    text = f"{kind} at t = {float(ev.get('t', 0.0)):.2f} s"
    if "agent" in ev:
        text += f": agent {ev['agent']}"
    text += f"; groups {_groups(ev.get('before'))} -> {_groups(ev.get('after'))}"
    if "cause" in ev:
        text += f" (cause: {ev['cause']})"
    level = LogLevel.Warning if kind == "agent_lost" else LogLevel.Info
    name = "membership" if kind.startswith("agent_") else "topology"
    return Log(timestamp=timestamp(ns), level=level, message=text, name=name)


class SceneChannels:
    """The channels above on one Context; the caller feeds instants in time order and the events."""

    def __init__(self, ctx: foxglove.Context, s: Scenario, ids: NDArray[np.int64], world_period_s: float = 1.0):
        self.s, self.ids = s, ids
        self.slots = np.asarray(s.target_m) + s.offsets
        self.world_period_s = world_period_s
        self._next_world = -math.inf
        self.world = SceneUpdateChannel(TOPIC_WORLD, context=ctx)
        self.swarm = SceneUpdateChannel(TOPIC_SWARM, context=ctx)
        self.events = LogChannel(TOPIC_EVENTS, context=ctx)
        self.errors = foxglove.Channel(TOPIC_TRACKING_ERROR, schema=tracking_error_schema(ids), context=ctx)
        self.metrics = foxglove.Channel(TOPIC_METRICS, schema=METRICS_SCHEMA, context=ctx)

    def tick(self, f: SwarmFrame, ns: int, max_error_m: float, min_agent_gap_m: float,
             min_obstacle_gap_m: float) -> None:
        """One instant: the swarm, the tracking errors, the metrics, and the world when it is due."""
        if f.t_s >= self._next_world - 1e-9:
            self.world.log(world_update(self.s, ns), log_time=ns)
            self._next_world = f.t_s + self.world_period_s
        self.swarm.log(swarm_update(f, ns), log_time=ns)
        self.errors.log(tracking_errors(f.t_s, self.ids, f.p, self.slots), log_time=ns)
        self.metrics.log({"t_s": f.t_s, "max_error_m": _num(max_error_m), "min_agent_gap_m": _num(min_agent_gap_m),
                          "min_obstacle_gap_m": _num(min_obstacle_gap_m), "groups": int(f.group.max()) + 1},
                         log_time=ns)

    def event(self, ev: dict[str, Any], ns: int) -> None:
        self.events.log(event_log(ev, ns), log_time=ns)


def _num(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None
