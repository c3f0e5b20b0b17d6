"""Co-hosted agents hear each other in their process: what one of a host's agents publishes, handed to the others.

The host's cell subscriptions take remote samples only (agent/listening.py), so a beacon or obstacle set one hosted
agent publishes reaches the others that listen to its cell here, at the host's next round: a beacon as the message
itself (under its handover label, agent/beacons.py: the bytes would decode to it), a set as its key and bytes with
the session as source (decoded once). Both are the host's own and believed without admission (no sample from zenoh
carries their tag, whatever source it is stamped with).

Two more things a hosted agent's own advanced subscriber would have done, kept here for the host:
- the newest admitted set of each publisher (remote, or co-hosted), replayed to an agent that starts listening to
  its cell later (what the history of a subscription of its own would have brought);
- each hosted agent's newest set puts (`ECHOES` of them), recognised when its publisher's cache hands them back to
  our own subscriptions' history queries (zenoh does not filter a query's replies by the allowed origin), even after
  the agent's next put (a restarted host would otherwise count them as forged).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

from reconswarm.net.runtime.inbox import Item, Tag
from reconswarm.net.wire import wire

ECHOES = 4  # a hosted agent's own sets recognised when they come back from its cache: its newest puts


class Loopback:
    """What co-hosted agents published since the host's last round, the sets kept for replay, the own puts."""

    def __init__(self, source: str, cohosted: bool) -> None:
        self.source = source  # the session's id: the source of what co-hosted agents hand each other
        self.cohosted = cohosted  # more than one agent in the process: anything to hand over at all
        # Published since the last round: a beacon with the message it was put from (nothing to decode again, 200 a
        # tick in a host of 200), a set as its bytes (decoded once).
        self.local: list[tuple[Tag, Item, wire.Beacon | None]] = []
        self.replay: list[tuple[int, Tag, Item]] = []  # (agent, tag, obstacle set) for that agent alone (replayed)
        self.sets: dict[int, tuple[Tag, Item]] = {}  # agent -> its newest obstacle set heard (its cell in its key)
        self.cached: dict[int, deque[tuple[str, bytes]]] = {}  # hosted agent -> its newest set puts (key, payload)

    def published(self, aid: int, put: tuple[str, bytes], out: wire.Beacon | wire.ObstacleSet, now_s: float) -> None:
        """Hosted agent aid put `out` (a beacon: its handover label and no bytes) under `put`."""
        if isinstance(out, wire.ObstacleSet):
            self.cached.setdefault(aid, deque(maxlen=ECHOES)).append(put)
        if not self.cohosted:
            return
        item = (put[0], put[1], "PUT", self.source, now_s)
        self.local.append((("local", aid), item, out if isinstance(out, wire.Beacon) else None))
        if isinstance(out, wire.ObstacleSet):
            self.sets[aid] = (("local", aid), item)  # (for an agent that starts listening to its cell later)

    def admitted(self, publisher: int, tag: Tag, item: Item) -> None:
        """A peer's set was admitted for the hosted agents (never one refused: it would stand in for the genuine)."""
        self.sets[publisher] = (tag, item)

    def newly_heard(self, aid: int, gained: Callable[[str], bool]) -> None:
        """Agent aid changed the cells it listens to (`gained(key)`: a key in a cell it hears now and did not
        before): the newest set of each publisher in those cells, for it alone at the next round."""
        self.replay += [(aid, tag, item) for tag, item in self.sets.values() if gained(item[0])]

    def echo(self, key: str, payload: bytes) -> bool:
        """A set a hosted agent put (one of its ECHOES newest), as its publisher's cache held it: a cell subscription
        declared after the put queries that cache, ours included, and the reply may leave before the agent's next
        put and arrive after it. Anything else with our session's id as its source (anyone can stamp it) goes
        through admission as before."""
        return any(k == key and p == payload for puts in self.cached.values() for k, p in puts)

    def take(self) -> tuple[list[tuple[int, Tag, Item]], list[tuple[Tag, Item, wire.Beacon | None]]]:
        """What the next round hands over: (the sets replayed to one agent, what co-hosted agents published)."""
        replay, local, self.replay, self.local = self.replay, self.local, [], []
        return replay, local

    def pending(self, others: Callable[[int, str], list[int]]) -> dict[int, int]:
        """How many inputs each hosted agent's next batch holds already (`others(sender, key)`: whom a co-hosted
        agent's publication is for)."""
        held: dict[int, int] = {}
        for aid, _tag, _item in self.replay:
            held[aid] = held.get(aid, 0) + 1
        for tag, item, _sent in self.local:
            for aid in others(tag[1], item[0]):
                held[aid] = held.get(aid, 0) + 1
        return held
