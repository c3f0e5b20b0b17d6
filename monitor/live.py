"""The live view: the monitor serves the run to the Foxglove app while it records (`--foxglove PORT`).

The same channels as the MCAP export (monitor/scene.py: `/world`, `/swarm`, `/tracking_error`, `/metrics`,
`/events`) through the Foxglove SDK's WebSocket server on 127.0.0.1:PORT, on a private Context, plus what
only the live swarm knows: `/knowledge` (`foxglove.SceneUpdate`), each agent's known obstacle hulls as
announced on its obstacle-set key (outlines in its group's colour, one entity per agent).

Fed from the ticks the monitor records: the scene goes out at most `max_rate_hz` times per wall second
(the app draws at display rate; a lockstep run records several hundred ticks a second) and nothing is
built while no client is subscribed, so serving costs the mission nothing measurable. Events go out as
they are recorded. Message times are the mission's wall-clock start plus simulated time (as in the export).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from typing import Any

import foxglove
import numpy as np
from foxglove.channels import SceneUpdateChannel
from foxglove.messages import (
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    SceneEntity,
    SceneEntityDeletion,
    SceneEntityDeletionType,
    SceneUpdate,
)
from numpy.typing import NDArray
from zenoh import ext

from monitor import scene
from monitor.messages import Scene
from reconswarm.errors import BadInput
from reconswarm.net.wire import wire
from reconswarm.net.wire.keys import Keys
from reconswarm.paper.events import Event
from reconswarm.paper.topology import labels
from reconswarm.scenario.model import Scenario

log = logging.getLogger("reconswarm.monitor")

HOST = "127.0.0.1"
DEFAULT_PORT = 8765
TOPIC_KNOWLEDGE = "/knowledge"
MAX_RATE_HZ = 20.0  # scenes per wall second at most
CLOSE_TIMEOUT_S = 2.0  # the server's stop waits for every client's queued messages: at most this long
SDK_LOG_LINES = 10  # the Foxglove SDK's log lines let through per SDK_LOG_WINDOW_S (the rest counted)
SDK_LOG_WINDOW_S = 60.0
KNOWLEDGE_Z_M = 0.2  # hull outlines just above the true obstacles


def knowledge_update(sets: dict[int, dict[str, NDArray[np.float64]]], group: dict[int, int], ns: int) -> SceneUpdate:
    """Every agent's known obstacle hulls: entity `knowledge/<id>` with one closed outline per hull, coloured
    by the agent's group (grey when it is in none). Replaces the previous update on its topic."""
    stamp = scene.timestamp(ns)
    ents = []
    for aid in sorted(sets):
        colour = scene.group_colour(group.get(aid, -1), 0.9)
        lines = [LinePrimitive(type=LinePrimitiveLineType.LineLoop, pose=scene.pose(0.0, 0.0), thickness=0.35,
                               points=[Point3(x=float(x), y=float(y), z=KNOWLEDGE_Z_M) for x, y in hull.tolist()],
                               color=colour)
                 for _, hull in sorted(sets[aid].items()) if hull.shape[0] >= 2]
        ents.append(SceneEntity(timestamp=stamp, frame_id=scene.FRAME, id=f"knowledge/{aid}", lines=lines))
    return SceneUpdate(deletions=[SceneEntityDeletion(timestamp=stamp, type=SceneEntityDeletionType.All)],
                       entities=ents)


class SdkLogBudget(logging.Filter):
    """At most `lines` log lines per `window_s` from the Foxglove SDK's loggers (`foxglove.*`: one per
    connection that fails its handshake, so one garbage client reconnecting wrote 6,470 lines); the next line
    let through says how many were not logged."""

    def __init__(self, lines: int = SDK_LOG_LINES, window_s: float = SDK_LOG_WINDOW_S) -> None:
        super().__init__()
        self.lines, self.window_s = lines, window_s
        self.window_start, self.used, self.dropped = -math.inf, 0, 0

    def filter(self, record: logging.LogRecord) -> bool:
        if not record.name.startswith("foxglove"):
            return True
        now = time.monotonic()
        if now - self.window_start >= self.window_s:
            self.window_start, self.used = now, 0
        if self.used >= self.lines:
            self.dropped += 1
            return False
        self.used += 1
        if self.dropped:
            record.msg, record.args = f"{record.getMessage()} ({self.dropped} more lines of the live view's server " \
                                      f"not logged)", None
            self.dropped = 0
        return True


SDK_LOG_BUDGET = SdkLogBudget()


def budget_sdk_logs() -> None:
    """Put the SDK's log lines on a budget at every handler of the root logger (the SDK logs through Python's
    logging under `foxglove.*`; a filter on a parent logger would not apply to its children's records)."""
    for handler in logging.getLogger().handlers:
        if SDK_LOG_BUDGET not in handler.filters:
            handler.addFilter(SDK_LOG_BUDGET)


class LiveView:
    """The WebSocket server and its channels; feed it ticks, obstacle sets and events in time order."""

    def __init__(self, s: Scenario, port: int, max_rate_hz: float = MAX_RATE_HZ, name: str = "reconswarm") -> None:
        self.s = s
        self.ids = np.asarray(s.ids, dtype=np.int64)
        self.index = {int(a): i for i, a in enumerate(self.ids)}
        self.period_s = 1.0 / max_rate_hz
        self.ctx = foxglove.Context()
        budget_sdk_logs()
        try:
            self.server = foxglove.start_server(name=name, host=HOST, port=port, context=self.ctx)
        except Exception as exc:  # the SDK's own error type: the port is taken or not allowed
            raise BadInput(f"--foxglove: cannot serve on {HOST}:{port} ({exc})") from None
        self.port = self.server.port
        self.channels = scene.SceneChannels(self.ctx, s, self.ids)
        self.knowledge = SceneUpdateChannel(TOPIC_KNOWLEDGE, context=self.ctx)
        self.sets: dict[int, dict[str, NDArray[np.float64]]] = {}
        self.start_ns: int | None = None
        self.next_s = 0.0
        self.group: dict[int, int] = {}
        self.scenes = 0  # scene updates sent on /swarm

    def _ns(self, t_s: float) -> int:
        if self.start_ns is None:
            self.start_ns = time.time_ns() - round(t_s * 1e9)
        return scene.stamp_ns(self.start_ns, t_s)

    def listened(self) -> bool:
        return bool(self.channels.swarm.has_sinks() or self.channels.world.has_sinks()
                    or self.knowledge.has_sinks() or self.channels.errors.has_sinks()
                    or self.channels.metrics.has_sinks())

    def due(self, now_s: float) -> bool:
        """Whether a scene would go out now (rate limit, and someone listening)."""
        return now_s >= self.next_s and self.listened()

    def tick(self, now_s: float, t_s: float, p: NDArray[np.float64], theta: NDArray[np.float64],
             alive: NDArray[np.bool_], edges: NDArray[np.int64], max_error_m: float, min_agent_gap_m: float,
             min_obstacle_gap_m: float) -> bool:
        """One recorded instant (arrays in scenario order, `edges` the swarm graph's index pairs); sent if due."""
        if not self.due(now_s):
            return False
        self.next_s = now_s + self.period_s
        active = alive & np.isfinite(p).all(axis=1)
        group = scene.group_index(labels(p.shape[0], edges, active))
        self.group = {int(a): int(g) for a, g in zip(self.ids, group, strict=True)}
        frame = scene.SwarmFrame(t_s, self.ids, p, theta, alive, self.s.radii, group, edges)
        ns = self._ns(t_s)
        self.channels.tick(frame, ns, max_error_m, min_agent_gap_m, min_obstacle_gap_m)
        self.knowledge.log(knowledge_update(self.sets, self.group, ns), log_time=ns)
        self.scenes += 1
        return True

    def obstacle_set(self, m: wire.ObstacleSet) -> None:
        self.sets[m.id] = {oid: np.array(v, dtype=np.float64).reshape(-1, 2) for oid, v in m.obstacles.items()}

    def event(self, ev: Event) -> None:
        self.channels.event(ev.to_dict(), self._ns(ev.t))

    def close(self, timeout_s: float = CLOSE_TIMEOUT_S) -> None:
        """Stop the server, waiting at most timeout_s: its stop waits until every client has taken what is
        queued for it, and clients that do not read (a full TCP window) held the monitor's shutdown until the
        launcher killed it. A stop still running then is left behind (a daemon thread: the process exits)."""
        stopper = threading.Thread(target=self.server.stop, name="live-view-stop", daemon=True)
        stopper.start()
        stopper.join(timeout_s)
        if stopper.is_alive():
            log.warning("live view: the server did not stop within %.0f s (clients not reading): left behind",
                        timeout_s)


class LiveFeed:
    """The zenoh side of the live view: the agents' obstacle sets (an advanced subscriber: sets announced
    before the monitor started come from the agents' caches), into the monitor's inbox: decoded and admitted
    by its port like every other sample (monitor/process.py), the admitted ones handed to the view."""

    def __init__(self, view: LiveView, keys: Keys, session: Any, handler: Any) -> None:
        self.view = view
        self.k = -1  # the newest tick sent
        self.sub = ext.declare_advanced_subscriber(session, keys.cell_agents(None, "obstacles"), handler,
                                                   history=ext.HistoryConfig(detect_late_publishers=True))

    def follow(self, sc: Scene, now_s: float) -> None:
        """The scene of the newest tick the node recorded, if it is new and one is due."""
        if sc.k != self.k and self.view.due(now_s):
            self.k = sc.k
            self.view.tick(now_s, sc.t_s, sc.p, sc.theta, sc.alive, sc.edges, sc.max_error_m, *sc.gaps_m)

    def close(self) -> None:
        self.sub.undeclare()
        self.view.close()


def status_table(sc: Scene | None, run: str) -> Any:
    """The terminal's live table (`monitor record --live`): the newest tick recorded (None: none yet)."""
    from rich.table import Table

    table = Table(title=f"reconswarm monitor — run {run}")
    for col in ("t (s)", "groups", "smallest gap (m)", "agents alive", "max |e| (m)", "rejected"):
        table.add_column(col)
    if sc is not None:
        table.add_row(f"{sc.t_s:.2f}", str(sc.n_groups), f"{sc.min_gap_m:.2f}",
                      f"{int(sc.alive.sum())}/{len(sc.alive)}", f"{sc.max_error_m:.2f}", str(sc.rejected))
    return table
