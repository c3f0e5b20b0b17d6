"""Who is alive, for every role: one pure module (no zenoh, no clock), one `Policy` per role, every threshold
from `Timing` (reconswarm/net/timing.py).

- the world (commands, or cmd_vel in ROS 2 mode) and the monitor (reports) judge by `Membership`: an agent is
  alive while its liveliness token is there AND its own data keeps coming (a token anyone can declare decides
  nothing alone: admission.py); `Policy.world` also stops counting a token whose agent keeps a lockstep tick
  waiting (`Membership.awaited`), `Policy.monitor` never does;
- an agent judges its peers by `living`: by their tokens until the world's clock says, then by the clock's
  live agents less those whose token it saw go (the world counts only agents whose commands come, so a forged
  token does not fool it); a peer alive so yet silent for `Policy.agent(...).fresh_s` is not waited for
  (`silent`), and is lost once the world's clock stops counting it; in realtime one unheard for `lately_s` (or
  3 periods) is not planned with (agent/neighbours.py `heard_lately`).

The roles' thresholds differ on purpose, and are ordered (tests/unit/test_membership_policy.py checks it): the
world and the monitor ask "is this agent still there" of data every agent sends at least every 0.5 s (commands or
stops, reports: `member_fresh_s`, 2 s); an agent asks "do I still wait for this peer's beacon", longer than a
frozen peer's lease (`peer_silent_s`, 3 s > `lease_ms`), so that a peer that is gone leaves by its token's end
first; the world's grace for a token that holds a tick up is longer than an agent's own wait for its peers.
"""

from __future__ import annotations

import math
from collections.abc import Set as AbstractSet
from dataclasses import dataclass, field

from reconswarm.net.node import Role
from reconswarm.net.timing import Timing


@dataclass(frozen=True)
class Policy:
    """How one role judges who is alive. Wall seconds, except `_sim_s` (simulated seconds).

    fresh_s / fresh_sim_s: an agent whose own data has been silent this long in both clocks is not alive
    (world, monitor); a peer silent this long of wall time is not waited for (agent). grace_s / grace_sim_s:
    the same for an agent not heard since its token appeared (or since the start). confirm_s: a token that
    goes counts as gone this much later, unless back by then. await_grace_s: a token whose agent keeps a
    tick waiting with nothing sent stops counting after this long (math.inf: never). relink_settle_s: once our
    own router link is back, tokens that went have this long to come back. stall_settle_s: after the caller
    itself stalled, tokens that go within this long are kept (0: the role does not settle). lately_s: realtime,
    a peer unheard this long (or 3 periods) is not planned with (agent; math.inf: no such rule).
    """

    role: Role  # whose policy (the role whose token it would be)
    fresh_s: float
    fresh_sim_s: float
    grace_s: float
    grace_sim_s: float
    confirm_s: float
    await_grace_s: float
    relink_settle_s: float
    stall_settle_s: float
    lately_s: float

    @classmethod
    def world(cls, t: Timing) -> Policy:
        # A token without commands does not hold a lockstep tick up beyond a grace longer than an agent's own
        # wait for its peers (`agent_wait_timeout_s`). After its own stall, the world keeps tokens that go for as
        # long as an agent waits for a silent peer (they come back as the sessions reconnect).
        return cls(Role.WORLD, t.member_fresh_s, t.member_fresh_sim_s, t.member_grace_s, t.member_grace_sim_s,
                   t.token_confirm_s, t.agent_wait_timeout_s + t.await_margin_s, t.relink_settle_s, t.peer_silent_s,
                   math.inf)

    @classmethod
    def monitor(cls, t: Timing) -> Policy:
        return cls(Role.MONITOR, t.member_fresh_s, t.member_fresh_sim_s, t.member_grace_s, t.member_grace_sim_s,
                   t.token_confirm_s, math.inf, t.relink_settle_s, 0.0, math.inf)

    @classmethod
    def agent(cls, t: Timing) -> Policy:
        # A peer's token that goes is gone at once (the world's clock, not its token, keeps a flapping peer
        # counted); its silence counts in wall time only (lockstep's simulated time stands while we wait), from
        # its token if it was never heard.
        return cls(Role.AGENT, t.peer_silent_s, math.inf, t.peer_silent_s, math.inf, 0.0, math.inf, 0.0, 0.0,
                   t.realtime_peer_silent_s)


def living(tokens: AbstractSet[int], gone: AbstractSet[int], counted: frozenset[int] | None,
           ) -> AbstractSet[int]:
    """An agent's live peers: `tokens` (whose tokens are there) until the world's clock says; then the clock's
    live agents (`counted`) less those whose token went (`gone`) and has not come back. The very sets given are
    returned where they are the answer (no copy: this runs for every wait of every tick)."""
    return tokens if counted is None else counted - gone if gone else counted


def silent(policy: Policy, heard_at: float, now: float) -> bool:
    """A peer last heard (its beacon, or its token's arrival) at wall time `heard_at` is silent at `now`: not
    waited for (a token without data: a frozen process before its lease ends, or a forged token)."""
    return now - heard_at >= policy.fresh_s


@dataclass
class Membership:
    """Who is alive: a liveliness token AND that agent's own data (beacons or commands) still coming.

    Before `start`, a token alone counts (nobody sends data before the first tick). Afterwards an agent with a
    token counts until it has been silent both `policy.fresh_s` of wall time and `policy.fresh_sim_s` of
    simulated time (so neither a stalled world, during which nobody sends, nor a fast realtime clock makes a
    live agent look dead); an agent not heard since its token appeared (or since the start) gets
    `policy.grace_s` / `policy.grace_sim_s` likewise. A token that goes counts as gone `policy.confirm_s` later
    (unless it is back by then); after the caller itself stalled (`settle`), a token that goes is kept for a
    while; while the caller's own session has no router (`link`), nobody is judged: every token goes at once
    then, and nobody's data can come. Times: `wall` (the caller's monotonic seconds), `sim` (the newest
    simulated time it knows).
    """

    policy: Policy
    started: tuple[float, float] | None = None
    tokens: dict[int, tuple[float, float]] = field(default_factory=dict)  # id -> (wall, sim) it appeared
    heard: dict[int, tuple[float, float]] = field(default_factory=dict)  # id -> (wall, sim) of its last data
    # A token that goes is gone `policy.confirm_s` later, unless it came back: a router that dies takes every
    # token with it a moment before the caller's session finds its own link gone (measured: the deletions come
    # first, with the router still listed, in 1 of 5 trials), so `link(False)` still comes in time.
    settle_until: float = -math.inf  # wall: a token that goes before then is kept (see settle)
    going: dict[int, float] = field(default_factory=dict)  # tokens that went, not yet judged: id -> wall it went
    unlinked: bool = False  # the caller's own session has no router (see link)
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

    def link(self, up: bool, wall: float, sim: float) -> None:
        """The caller's own session lost its router (up=False: a router that died or froze takes every token with it,
        and nobody's data can reach us) or has one again (up=True, also when it is a new router). While it
        has none nobody is judged; once back, tokens that went have `policy.relink_settle_s` to come back,
        and everyone's data is awaited afresh (the grace, as after the start)."""
        self.unlinked = not up
        if up:
            self.settle_until = max(self.settle_until, wall + self.policy.relink_settle_s)
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
            if wall >= max(went + self.policy.confirm_s, self.settle_until):
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
        sent nothing since the wait began stops counting `policy.await_grace_s` later, until its data comes."""
        if self.started is None or self.unlinked or wall < self.settle_until or agent_id not in self.tokens:
            return
        last = self.heard.get(agent_id)
        if (last is None or last[0] < since_wall) and wall - since_wall > self.policy.await_grace_s:
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
        last, p = self.heard.get(agent_id), self.policy
        if last is not None and last[0] >= since[0]:
            return wall - last[0] <= p.fresh_s or sim - last[1] <= p.fresh_sim_s
        ref = (max(since[0], self.started[0]), max(since[1], self.started[1]))
        return wall - ref[0] <= p.grace_s or sim - ref[1] <= p.grace_sim_s

    def alive_ids(self, wall: float, sim: float) -> list[int]:
        self._judge(wall)
        return sorted(a for a in list(self.tokens) if self.alive(a, wall, sim))
