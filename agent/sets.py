"""The peers' obstacle sets an agent holds, by revision, and which revisions it merged already; its own scans
as obstacle sets (pure)."""

from __future__ import annotations

import numpy as np

from reconswarm.net.wire import wire

ObstacleSets = dict[str, np.ndarray]


class PeerSets:
    def __init__(self) -> None:
        self.sets: dict[int, dict[int, ObstacleSets]] = {}  # peer -> rev -> obstacle sets
        # Revisions already merged (into the brain's own set / the leader's union): merging a set again
        # cannot change a hull, so it is skipped.
        self.merged: dict[int, int] = {}
        self.merged_union: dict[int, int] = {}

    def add(self, m: wire.ObstacleSet) -> None:
        self.sets.setdefault(m.id, {})[m.rev] = {oid: np.array(v, dtype=np.float64) for oid, v in m.obstacles.items()}

    def unmerged(self, wanted: dict[int, int], merged: dict[int, int]) -> list[ObstacleSets]:
        """The sets at the wanted revisions that are not merged yet (and mark them merged)."""
        out = []
        for a in sorted(wanted):
            rev = wanted[a]
            if rev == 0 or merged.get(a, 0) >= rev:
                continue
            out.append(self.latest(a, rev))
            merged[a] = rev
        return out

    def newest(self) -> dict[int, int]:
        """Each peer's newest revision held."""
        return {a: max(revs) for a, revs in self.sets.items() if revs}

    def latest(self, peer: int, rev: int | None) -> ObstacleSets:
        revs = self.sets.get(peer, {})
        if rev is not None and rev in revs:
            return revs[rev]
        usable = [r for r in revs if rev is None or r <= rev]
        return revs[max(usable)] if usable else {}

    def prune(self, leader: bool) -> None:
        """Keep the newest merged revision of each peer and everything after it."""
        for a, revs in self.sets.items():
            done = min(self.merged.get(a, 0), self.merged_union.get(a, 0) if leader else 2**62)
            for r in [r for r in revs if r < done]:
                del revs[r]


def scan_sets(scans: dict[int, wire.Scan], k_from: int, k_to: int) -> dict[str, list[tuple[float, float]]]:
    """The points (x, y) of our scans of ticks k_from..k_to by obstacle, in scan order (those scans are taken
    out of `scans`); kept as the wire's tuples: most of them were seen already (agent/brain.py)."""
    pts: dict[str, list[tuple[float, float]]] = {}
    for kk in range(k_from, k_to + 1):
        sc = scans.pop(kk, None)
        if sc is not None:
            for x, y, oid in sc.points:
                pts.setdefault(oid, []).append((x, y))
    return pts


def own_set(agent_id: int, k: int, rev: int, hulls: ObstacleSets) -> wire.ObstacleSet:
    """An agent's own obstacle set (obstacle id -> hull (V, 2)) as the message it announces at tick k."""
    return wire.ObstacleSet(agent_id, k, rev, {oid: tuple((float(x), float(y)) for x, y in h.tolist())
                                               for oid, h in hulls.items()})
