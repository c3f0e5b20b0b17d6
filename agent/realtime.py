"""Realtime, as an agent's node keeps it (agent/node.py `pace`): the world steps every period whatever came, so the
node acts on its newest state with whatever it has: the peers' latest beacons and obstacle sets.

On a new state the node announces its beacon at once and acts as soon as the beacons of that tick from the peers
whose latest beacon may matter (heard lately, within reach: agent/neighbours.py `near_now`) are in, or at its
deadline, `realtime_act_fraction` of a period after the state arrived (the runtime wakes it then: `wake_at_s`).
It plans with the live peers heard lately that are within reach, or whose robots its scan reports held near it,
and merges the newest set of each peer within link range. Nothing here is a guess: realtime is not meant to repeat.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from collections.abc import Set as AbstractSet

import numpy as np

from agent.brain import Body
from agent.pace import Paced
from reconswarm.net.wire import wire


class Realtime:
    """The newest tick, at once when its peers' beacons are in, or at its deadline."""

    holds_awaiting = False  # `AgentNode.awaiting` counts afresh at every call

    @staticmethod
    def next_tick(node: Paced) -> int:
        return max(node.h.states, default=-1)

    def advance(self, node: Paced, now: float) -> None:
        """Act on the newest state once the peers' beacons for it are in, or at its deadline."""
        k = self.next_tick(node)
        if k <= node.k:
            return
        if node.beacon_sent < k:
            node.move(k, node.h.states[k])
            node.out.append(node.beacon(node.h.states[k]))
            node.beacon_sent = k
        fresh = node.h.beacons.get(k, {})
        due = node.act_at is not None and now >= node.act_at
        if due or all(a in fresh for a in self.expected(node, k, None)):
            node.act_at = None
            node.act(k, now)

    @staticmethod
    def lately(node: Paced) -> set[int]:
        """The live peers heard within `lately_s` (or a few periods)."""
        return node.nb.heard_lately(node.h.alive, node.h.heard, node.now, node.period_s, node.policy.lately_s)

    def expected(self, node: Paced, k: int, clock: wire.Clock | None) -> AbstractSet[int]:
        """The peers whose beacon of tick k the node waits for until its deadline: those heard lately whose latest
        beacon may matter."""
        p = (node.h.states[k].px, node.h.states[k].py)
        return node.nb.near_now(p, self.lately(node), node.h.last_seen)

    @staticmethod
    def more_needed(node: Paced, k: int, clock: wire.Clock | None, fresh: Mapping[int, wire.Beacon],
                    waited: AbstractSet[int]) -> int:
        return 0

    def wanted(self, node: Paced, k: int, p: tuple[float, float]) -> AbstractSet[int]:
        """The live peers tick k plans with at their latest beacon when their beacon of k lacks: those heard lately
        and within reach, and those whose robots our scan reports held near us."""
        sc = node.h.scans.get(k)
        held = {a for a, _x, _y in sc.bodies} if sc is not None else set()
        seen = node.h.last_seen
        return {a for a in self.lately(node) | held if a in held or (a in seen and node.nb.audible(p, seen[a]))}

    @staticmethod
    def on_state(node: Paced, now: float) -> None:
        """Our state came: act by the deadline, a fraction of a period from now."""
        node.act_at = now + node.timing.realtime_act_fraction * node.period_s

    @staticmethod
    def quiet(node: Paced, now: float) -> bool:
        """The world stalls: its token is gone (a silence is no stall: the world keeps its own time)."""
        return node.world_gone

    @staticmethod
    def loses_in_flight(node: Paced) -> bool:
        return False

    @staticmethod
    def check_late(node: Paced, k: int) -> None:
        """Nothing comes late in realtime: a tick acts on what it has."""

    @staticmethod
    def linked_sets(node: Paced, k: int, p: np.ndarray, peers: Sequence[Body], lost: Sequence[Body]) -> dict[
            int, int]:
        """The sets tick k merges: the newest of each peer within link range."""
        return {a: max(node.sets.get(a, {0: {}})) for a in node.brain.linked(p, [*peers, *lost])}

    @staticmethod
    def swarm_revisions(node: Paced, k: int) -> dict[int, int]:
        """The virtual leader's: every peer's newest set."""
        return node.peer_sets.newest()

    @staticmethod
    def living_at(node: Paced, k: int) -> AbstractSet[int]:
        return set()


REALTIME = Realtime()
