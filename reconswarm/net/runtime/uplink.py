"""Whether this process's own session still reaches its router.

A client session (every process of a run but the routers) lists the routers it is connected to
(`session.info.routers_zid()`, zenoh-python 1.10). When that router dies (or freezes past the lease), the
list goes empty and every liveliness token learnt through it is deleted at once: that is this process's
link going, not every agent dying. The client reconnects by itself when a router listens again on the
endpoint (a restarted one has a new id), and the tokens come back. `Uplink.poll` tells the runtime
(net/runtime/runtime.py: every node gets a `RouterReach`) when the link goes and comes back, so that each role's
membership (`Membership`) judges nobody meanwhile.
"""

from __future__ import annotations

import logging
import time
from contextlib import suppress
from enum import Enum
from typing import Any

log = logging.getLogger("reconswarm")


class LinkChange(Enum):
    DOWN = "down"  # the session has no router any more
    UP = "up"  # it has one again (or a different one: a router restarted between two polls)


def router_ids(session: Any) -> frozenset[str]:
    """The ids of the routers this session is connected to (empty if it cannot tell)."""
    with suppress(Exception):
        return frozenset(str(z) for z in session.info.routers_zid())
    return frozenset()


def neighbours(session: Any) -> str:
    """Whom a session is connected to, for its log: its zenoh mode's direct neighbours, routers and peers (a peer
    of a run in `--zenoh-mode peer` has the run's other processes among them)."""
    with suppress(Exception):
        routers, peers = list(session.info.routers_zid()), list(session.info.peers_zid())
        return f"{len(routers)} router{'s' * (len(routers) != 1)}, {len(peers)} peer{'s' * (len(peers) != 1)}"
    return "neighbours unknown"


class Uplink:
    """Follows a session's routers; a session that had none when opened (a peer, a router) is not followed.

    The routers are read at most every `POLL_S` (reading them costs about 10 µs, and the runtime polls several
    times a tick): a link that goes is told that much later, far within zenoh's lease of seconds."""

    POLL_S = 0.02

    def __init__(self, session: Any, who: str) -> None:
        self.session, self.who = session, who
        self.routers = router_ids(session)
        self.followed = bool(self.routers)
        self.down = False
        self._read_at = time.monotonic()

    def links(self) -> str:
        """`neighbours` of the session (for its log)."""
        return neighbours(self.session)

    def poll(self) -> LinkChange | None:
        """What changed since the routers were last read (they are read again once `POLL_S` has passed)."""
        if not self.followed:
            return None
        at = time.monotonic()
        if at - self._read_at < self.POLL_S:
            return None
        self._read_at = at
        now = router_ids(self.session)
        if now == self.routers:
            return None
        before, self.routers = self.routers, now
        if not now:
            self.down = True
            log.warning("%s: the router is gone (our own session's link): nobody's membership is judged until "
                        "it is back", self.who)
            return LinkChange.DOWN
        if self.down or before:
            log.warning("%s: connected to a router again (%s)", self.who, ", ".join(sorted(now)))
        self.down = False
        return LinkChange.UP
