"""Truth-side bookkeeping shared by the in-process engine and the monitor process: per tick, the safety
metrics, the swarm graph's split / merge events and the row of run.db."""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from reconswarm.paper.events import Event
from reconswarm.paper.topology import TopologyTracker
from reconswarm.plant.sensing import ContourField
from reconswarm.record.safety import Episode, SafetyMonitor
from reconswarm.scenario.model import Scenario

Array = NDArray[np.float64]


class Rows(Protocol):
    """Where the recorder's rows go: the record itself (store.RunWriter, the engine's), or the monitor's node's
    outputs, which its process hands to the record (monitor/rows.py)."""

    def tick(self, k: int, t: float, p: Array, theta: Array, alive: NDArray[np.bool_], max_error_m: float,
             min_agent_gap_m: float, min_obstacle_gap_m: float, groups: int) -> None: ...

    def event(self, ev: Event) -> None: ...

    def episode(self, e: Episode) -> None: ...

    def episode_end(self, key: tuple[str, str, str], t: float) -> None: ...


class Recorder:
    """Truth-side bookkeeping shared by the engine and the monitor process: safety, topology, run.db."""

    def __init__(self, s: Scenario, writer: Rows | None) -> None:
        self.s = s
        self.writer = writer
        self.ids = s.ids
        self.slots = np.asarray(s.target_m) + s.offsets
        self.field = ContourField.from_scenario(s)
        self.topology = TopologyTracker(self.ids, s.planner.link_range_m)
        self.events: list[Event] = []  # every event recorded, in order
        self.max_error_m = float("inf")
        self.gaps_m = (float("inf"), float("inf"))  # the latest tick's smallest agent and obstacle gaps
        p_cfg = s.planner
        # Pairs within this distance cover the swarm graph (link + hysteresis) and the safety reach.
        self.reach_m = max(p_cfg.link_range_m + self.topology.hysteresis_m, 2 * float(s.radii.max()) + p_cfg.d_max_m)
        self.safety = SafetyMonitor(self.ids, s.radii, self.field.ids, p_cfg.d_safe_m,
                                    self.reach_m - 2 * float(s.radii.max()))

    def tick(self, k: int, t: float, p: Array, theta: Array, alive: NDArray[np.bool_],
             true_d: Array | None = None, cand: NDArray[np.int64] | None = None, *,
             cand_d: Array | None = None, err: Array | None = None) -> list[Event]:
        """Record the truth at tick k; returns the topology events confirmed now (already recorded).

        true_d (N, M) and cand (pairs within `self.reach_m`) may be passed when already computed, and with
        cand the pairs' norm2 distances cand_d (E,); err (N,) likewise norm2(p - slots).
        """
        if true_d is None:
            true_d = self.field.true_distances(p)
        if cand is None:
            cand_d = None
        if err is None:
            rel = p - self.slots  # (N, 2)
            x, y = rel[:, 0], rel[:, 1]
            err = np.sqrt(x * x + y * y)  # the sum over the two columns, written out
        if alive.all():
            self.max_error_m = float(err.max())
        else:
            self.max_error_m = float(err[alive].max()) if alive.any() else float("inf")
        gap_a, gap_o, started, ended = self.safety.step(t, p, true_d, cand, cand_d)
        self.gaps_m = (gap_a, gap_o)
        events = [Event.from_dict(e) for e in self.topology.step(t, p, alive, cand, cand_d)]
        for ev in events:
            self.event(ev)
        if self.writer is not None:
            w = self.writer
            for ep in started:
                w.episode(ep)
            for key in ended:
                w.episode_end(key, t)
            w.tick(k, t, p, theta, alive, self.max_error_m, gap_a, gap_o, self.topology.n_groups)
        return events

    def event(self, ev: Event) -> None:
        """The one way an event enters the record (the monitor publishes the same object after this)."""
        self.events.append(ev)
        if self.writer is not None:
            self.writer.event(ev)

    def converged(self) -> bool:
        return self.max_error_m <= self.s.planner.converge_tol_m
