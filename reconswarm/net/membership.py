"""Membership: who is alive, by a liveliness token AND that agent's own data (admission.py's last rule).

A liveliness token anyone can declare decides nothing alone: the world (commands, or cmd_vel in ROS 2 mode)
and the monitor (reports) count an agent alive while its token is there and its own data keeps coming.
Pure: no zenoh.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field


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
    # A caller waiting for an agent's data (`awaited`) stops counting its token after this much silence.
    await_grace_s: float = 4.0
    mute: set[int] = field(default_factory=set)  # tokens that stopped counting while awaited, until data comes

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
                self.mute.clear()

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
                self.mute.discard(a)
                del self.going[a]

    def data(self, agent_id: int, wall: float, sim: float) -> None:
        self.heard[agent_id] = (wall, sim)
        self.mute.discard(agent_id)

    def awaited(self, agent_id: int, since_wall: float, wall: float) -> None:
        """The caller has been waiting for this agent's data since `since_wall` (a lockstep tick). Silence
        counts in simulated time too (`alive`), and sim time stands still while the caller waits: a token
        alone (anyone can declare one for a dead agent) would hold it up for good. So a token whose agent has
        sent nothing since the wait began stops counting `await_grace_s` later, until its data comes."""
        if self.started is None or self.unlinked or wall < self.settle_until or agent_id not in self.tokens:
            return
        last = self.heard.get(agent_id)
        if (last is None or last[0] < since_wall) and wall - since_wall > self.await_grace_s:
            self.mute.add(agent_id)

    def alive(self, agent_id: int, wall: float, sim: float) -> bool:
        if self.going:
            self._judge(wall)
        since = self.tokens.get(agent_id)
        if since is None:
            return False
        if self.started is None or self.unlinked:
            return True
        if agent_id in self.mute:
            return False
        last = self.heard.get(agent_id)
        if last is not None and last[0] >= since[0]:
            return wall - last[0] <= self.fresh_s or sim - last[1] <= self.fresh_sim_s
        ref = (max(since[0], self.started[0]), max(since[1], self.started[1]))
        return wall - ref[0] <= self.grace_s or sim - ref[1] <= self.grace_sim_s

    def alive_ids(self, wall: float, sim: float) -> list[int]:
        self._judge(wall)
        return sorted(a for a in list(self.tokens) if self.alive(a, wall, sim))
