"""A process's runtime: one zenoh session, one inbox, the nodes it hosts (one or many) stepped with what arrived.

Every process of a run is this loop (the agent host, the world, the monitor), around nodes that keep the
node contract (reconswarm/net/node.py) and a `Adapter`, the role's declarations: its subscriptions feed the
inbox, `route` turns a batch of raw samples into each node's inputs (the table from key to codec to input,
with admission and rejection counting: what a node is given is believed), `act` does what a node returned
(put a message on the wire under its key or ROS 2 topic, hand rows to the record). The runtime owns the rest:

- one wake-up per batch: it sleeps until the nodes' count of what they still need is in (`awaiting`, less what
  a co-hosting adapter holds for each without a sample to come: what co-hosted nodes published), the urgent samples of
  the nodes that need one to act came (an agent's state; the inbox may go on with some after a short while),
  the nearest node timer is due (`wake_at_s`), or `poll_s` passed; at once if what the adapter holds is all a
  node still needs;
- a node is stepped when it has inputs, when its timer is due, or every `poll_s` (its timers);
- after a round of steps a adapter that hosts nodes talking to each other (`CoHosting`: an agent host) may answer
  what the nodes asked in it, together (`answers`: its law for all its agents' plans at once): those nodes are
  stepped with the answers at once, until none is left;
- our own session's router link going or coming back reaches every node as `RouterReach` (net/runtime/uplink.py);
- SIGINT/SIGTERM (the `Stopper`) reach every node as `Stop`: each winds down and says what happened (its
  `Exit`); a node's `Exit` takes it out of the loop, the others go on;
- the `usage at start` mark once the mission started (benchmarks take CPU per tick from it).

Signals, the parent watch and logging are set up once by `net/runtime/session.serving`, which opens the session.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from typing import Any, Protocol

from reconswarm.net.node import Exit, Node, RouterReach, Stop
from reconswarm.net.runtime.lifecycle import StartMark, Stopper
from reconswarm.net.runtime.uplink import LinkChange, Uplink


class Batches(Protocol):
    """An inbox: `take` every sample waiting once `want` of them (None: only urgent ones) are in, `urgent` urgent
    ones came (from as many nodes; an inbox may go on with fewer after a short while), or `timeout` seconds
    passed (net/runtime/inbox.Inbox: each sample with the subscription it came through)."""

    def take(self, want: int | None, timeout: float | None, urgent: int = 1) -> Sequence[Any]: ...


class Adapter(Protocol):
    """A role's declarations around the nodes a process hosts (keyed by any hashable: an agent's id, 0)."""

    def route(self, items: Sequence[Any], now_s: float) -> Mapping[Any, list[Any]]:
        """Each node's inputs from a batch of samples: decoded once, admitted, malformed ones counted."""
        ...

    def act(self, who: Any, out: Any, now_s: float) -> bool:
        """Do what node `who` returned; True: stop the whole loop now (e.g. its session must be replaced)."""
        ...

    def idle(self, who: Any, now_s: float) -> None:
        """After node `who`'s step: its periodic chores (its report, the record's commit)."""
        ...

    def exited(self, who: Any, code: Exit, now_s: float) -> None:
        """Node `who` left the loop with `code` (the others go on)."""
        ...


class CoHosting(Protocol):
    """What a adapter that hosts nodes which talk to each other adds to `Adapter` (an agent host: agent/host.py)."""

    def pending(self) -> Mapping[Any, int]:
        """How many inputs wait for each node that need no sample to arrive (what co-hosted nodes published): its
        next batch has them, whenever it comes."""
        ...

    def answers(self, now_s: float) -> Mapping[Any, list[Any]]:
        """After a round of steps: inputs the adapter computed for nodes from what they returned in it, together (an
        agent host's law for all its agents' plans at once); the nodes are stepped with them at once."""
        ...


class _Alone:
    """A adapter's co-hosting when it has none (the world's, the monitor's): nothing held, nothing answered."""

    def pending(self) -> Mapping[Any, int]:
        return {}

    def answers(self, now_s: float) -> Mapping[Any, list[Any]]:
        return {}


class Runtime:
    """The loop around the nodes of one process, on one session (see the module's notes)."""

    def __init__(self, session: Any, who: str, stop: Stopper, inbox: Batches, poll_s: float) -> None:
        self.uplink = Uplink(session, who)
        self.stop, self.inbox, self.poll_s = stop, inbox, poll_s
        self.exits: dict[Any, Exit] = {}  # node -> how it left
        self.interrupted = False  # a adapter's act asked the whole loop to stop

    def run(self, nodes: Mapping[Any, Node[Any, Any]], adapter: Adapter, started: Any = lambda: True,
            cohosting: CoHosting | None = None) -> dict[Any, Exit]:
        """Step the nodes until each has exited (or a adapter's `act` stops the loop); how each left. cohosting: what
        the adapter holds for and answers to nodes that talk to each other (none by default)."""
        active, co = dict(nodes), cohosting or _Alone()
        stepped: dict[Any, float] = {}
        mark, stopping = StartMark(self.uplink.links), False
        while active:
            mark(started())
            now = time.monotonic()
            held = co.pending()
            awaiting = [(who, n.awaiting(now)) for who, n in active.items()]
            needs = [w - held.get(who, 0) for who, w in awaiting if w is not None]
            wakes = [w for w in (n.wake_at_s() for n in active.values()) if w is not None]
            # (what the adapter holds may all be in a node's count of what it needs: then nothing need arrive)
            timeout = 0.0 if any(w <= 0 for w in needs) else self.poll_s if not wakes else min(
                self.poll_s, max(0.0, min(wakes) - now))
            # (the nodes that need an urgent sample of their own to act: their states, which come in one burst)
            items = self.inbox.take(max(1, min(needs)) if needs else None, timeout, len(awaiting) - len(needs))
            now = time.monotonic()
            shared: list[Any] = []
            if (change := self.uplink.poll()) is not None:
                shared.append(RouterReach(change is LinkChange.UP))
            if self.stop.stopped and not stopping:
                stopping = True
                shared.append(Stop())
            batches = adapter.route(items, now)
            if self._round(list(active), active, adapter, batches, shared, stepped):
                return self.exits
            while answers := co.answers(time.monotonic()):  # (a node's answer may lead it to ask again)
                if self._round([w for w in active if w in answers], active, adapter, answers, [], stepped):
                    return self.exits
        return self.exits

    def _round(self, who_steps: list[Any], active: dict[Any, Node[Any, Any]], adapter: Adapter,
               batches: Mapping[Any, Sequence[Any]], shared: list[Any], stepped: dict[Any, float]) -> bool:
        """Step those of the active nodes with inputs (or timers due) and do what each returns, in order; a node that
        exits leaves `active`. True: the adapter stopped the loop."""
        for who in who_steps:
            node = active[who]
            batch = [*shared, *batches.get(who, ())]
            now, wake = time.monotonic(), node.wake_at_s()
            if not batch and now - stepped.get(who, -math.inf) < self.poll_s and (wake is None or now < wake):
                continue  # nothing new for it, and none of its timers due
            stepped[who] = now
            for out in node.step(batch, now):
                if isinstance(out, Exit):
                    self.exits[who] = out
                    del active[who]
                    adapter.exited(who, out, now)
                    break
                if adapter.act(who, out, now):
                    self.interrupted = True
                    return True
            else:
                adapter.idle(who, now)
        return False
