"""What an agent has heard, by tick (pure: no clock, no I/O): the world's states, scans and clocks for it, the
peers' beacons and each peer's newest, when each peer was last heard, and who is alive.

"Alive" is decided here once (`living`, by the agent's rule in reconswarm/net/trust/membership.py): by its token; once a
clock says, counted by the world's clock and not seen going by its token. Not the tokens alone there: the world saw
a token whose news to us may come after the clock (a token's declaration and the world's data need not come in
the order the world saw them), and a forged token does not fool the world's clock.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from collections.abc import Set as AbstractSet

from reconswarm.net.trust import membership
from reconswarm.net.wire import wire


class Heard:
    def __init__(self, agent_id: int) -> None:
        self.id = agent_id
        self.states, self.scans, self.clocks = dict[int, wire.State](), dict[int, wire.Scan](), dict[int, wire.Clock]()
        self.beacons: dict[int, dict[int, wire.Beacon]] = {}  # tick -> peer -> its beacon at that tick
        self.last_seen: dict[int, wire.Beacon] = {}  # peer -> its newest beacon (a lost peer stays there)
        self.alive, self.gone = set[int](), set[int]()  # (gone: peers whose token we saw go, and not come back)
        # Tokens that went, not yet gone (`confirm`): peer -> wall time it went. A dying router takes every token
        # with it a moment before our session finds its own link gone; while it is gone nobody's token is judged.
        self.going: dict[int, float] = {}
        self.judge_from = -math.inf  # (wall: tokens that went are judged from then on; see `hold`)
        self.tokens = 0  # how many token changes came (what `living` says changes only with one, or a new clock)
        self.heard: dict[int, float] = {}  # wall time of each peer's latest beacon (or of its token), the newest last
        self.state_at: dict[int, float] = {}  # wall time each tick's state arrived (lockstep: while its clock is due)
        self._counted: tuple[int, ...] | None = None  # the newest clock's live agents (`clock`)

    def beacon(self, m: wire.Beacon, now: float) -> None:
        a, k, heard = m.id, m.k, self.heard  # (most of what arrives: its fields read once)
        if (tick := self.beacons.get(k)) is None:
            tick = self.beacons[k] = {}
        tick[a] = m
        heard.pop(a, None)  # (kept in the order of its times: the newest last)
        heard[a] = now
        if (seen := self.last_seen.get(a)) is None or k >= seen.k:
            self.last_seen[a] = m

    def token(self, agent: int, up: bool, now: float) -> None:
        """A peer's token came (up) or went (gone once `confirm` says so)."""
        self.tokens += 1
        (self.alive.add if up else self.alive.discard)(agent)
        if up:
            self.gone.discard(agent)
            self.going.pop(agent, None)
            self.heard.setdefault(agent, now)
        elif agent not in self.gone:
            self.going.setdefault(agent, now)

    def hold(self, until: float) -> None:
        """Judge no token that went before `until` (our own link down, or back: tokens have until then to return)."""
        self.judge_from = max(self.judge_from, until)

    def confirm(self, now: float, confirm_s: float) -> bool:
        """The tokens that went `confirm_s` ago (and not before `judge_from`) are gone. True if any."""
        due = [a for a, at in self.going.items() if now - max(at, self.judge_from) >= confirm_s]
        for a in due:
            del self.going[a]
            self.gone.add(a)
        self.tokens += bool(due)
        return bool(due)

    def scan(self, m: wire.Scan, radius: dict[int, float]) -> None:
        """Our scan; the robots it says are held near us (their agents gone; maybe never heard: lost far away)."""
        self.scans[m.k] = m
        self.last_seen.update((a, wire.Beacon(a, m.k, m.t, x, y, radius[a])) for a, x, y in m.bodies
                              if a in radius and a != self.id)

    def clock(self, m: wire.Clock, now: float) -> None:
        self.clocks[m.k] = m
        if m.alive is self._counted or m.alive == self._counted:  # (each heard since, or alive or gone by its token)
            return
        self._counted = m.alive
        for a in m.alive_set.difference(self.alive, self.gone) - {self.id}:  # counted before its token came:
            self.heard.setdefault(a, now)  # its silence counts from now

    def living(self, clock: wire.Clock | None) -> AbstractSet[int]:
        """The one notion of a live peer (membership.living); clock: the tick's (None: tokens alone)."""
        return membership.living(self.alive, self.gone, None if clock is None else clock.alive_set)

    def lacks(self, k: int, waited: AbstractSet[int], linked: Mapping[int, int],
              sets: Mapping[int, Mapping[int, object]]) -> str:
        """What tick k still lacks (for the log): its state, its clock, the beacons of the peers it waits for,
        the sets of the linked peers' revisions (peer -> revision) not in `sets` (peer -> revision -> set)."""
        if k not in self.states:
            newest = max(self.states, default=None), max(self.clocks, default=None)
            return f"tick {k}: no state yet (newest state {newest[0]}, newest clock {newest[1]})"
        fresh = self.beacons.get(k, {})
        peers = sorted(a for a in waited if a not in fresh)
        missing = sorted(a for a, rev in linked.items() if rev not in sets.get(a, ()))
        what = (["clock"] * (k not in self.clocks) + [f"beacons of {peers}"] * bool(peers)
                + [f"obstacle sets of {missing}"] * bool(missing))
        return f"tick {k}: waiting for {', '.join(what) or 'nothing'}"

    def newest_clock(self) -> wire.Clock | None:
        return self.clocks.get(max(self.clocks, default=-1))

    def silent_since(self, now: float) -> None:
        """Every peer's silence, and every wait for a tick's data, counts from now at the earliest (the world
        stalled: nobody had a state to announce)."""
        for store in (self.heard, self.state_at):
            for a, at in store.items():
                store[a] = max(at, now)

    def forget_stale(self, audible: Callable[[wire.Beacon], bool], living: AbstractSet[int], stale_k: int) -> None:
        """Forget where live peers (by token) were last heard once stale: out of the cells we listen to (not
        `audible`), or alive by the world's clock (commanding: `living`) yet unheard since before tick stale_k."""
        for a in [a for a, b in self.last_seen.items()
                  if a in self.alive and (not audible(b) or (a in living and b.k < stale_k))]:
            del self.last_seen[a]

    def prune(self, k: int) -> None:
        """Forget the ticks before k - 2."""
        for store in (self.states, self.clocks, self.beacons, self.scans, self.state_at):
            for kk in [x for x in store if x < k - 2]:
                del store[kk]
