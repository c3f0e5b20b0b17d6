"""Who is there, for the monitor's node (monitor/node.py): the one place the monitor decides which agents are alive.

An agent is alive while its liveliness token is there AND its own reports (its heartbeat) keep coming
(net/trust/membership.Membership, fed by the node with the tokens, the reports and our own router link). A change
is an event: an agent that goes is `agent_lost`, one that comes back `agent_joined` (the first tokens are not
joins); several lost within `burst_s` while others stay is the network splitting (a `split`, cause
"network"), their return a `merge`. Changes are not judged once the mission ended (agents leave then), and
are held while the world stalls (agents reconnect when nothing moves) until the node judges them.
"""

from __future__ import annotations

import logging

import numpy as np

from reconswarm.net.timing import Timing
from reconswarm.net.trust.membership import Membership, Policy
from reconswarm.paper.events import Event, EventKind, Groups

log = logging.getLogger("reconswarm.monitor")


def _g(*groups: list[int]) -> Groups:
    return tuple(tuple(g) for g in groups)


class Presence:
    def __init__(self, ids: list[int], timing: Timing, unix_offset_s: float) -> None:
        self.ids, self.timing, self.unix_offset_s = ids, timing, unix_offset_s
        self.index = {a: k for k, a in enumerate(ids)}
        self.members = Membership(Policy.monitor(timing))
        self.told: dict[int, bool] = {}  # agent -> alive as last judged by the membership
        self.alive = np.zeros(len(ids), dtype=bool)  # alive as recorded (scenario order)
        self.seen = np.zeros(len(ids), dtype=bool)
        self.burst_lost: list[int] = []  # agents lost in the current burst (network split detection)
        self.burst_lost_at = self.burst_lost_t = 0.0
        self.burst_before: list[int] = []
        self.burst_back: list[int] = []
        self.burst_back_at = self.burst_back_t = 0.0
        self.partitioned: set[int] = set()
        self.deferred: dict[int, bool] = {}  # agent -> its latest state by the membership, held during a stall

    def _wall(self, now_s: float) -> float:
        return round(now_s + self.unix_offset_s, 6)

    def alive_ids(self) -> list[int]:
        return [int(a) for a in np.array(self.ids)[self.alive]]

    def sync(self, now_s: float, t: float, started: bool, ended: bool, held: bool) -> list[Event]:
        """Judge everyone by the membership rule (`started`: the mission's first clock came), as it changes:
        the events (none once `ended`; held for `judge` while `held`)."""
        if started:
            self.members.start(now_s, t)
        out: list[Event] = []
        for aid in self.ids:
            up = self.members.alive(aid, now_s, t)
            if self.told.get(aid, False) != up:
                if ended:  # agents leave when the mission ends: not a loss (judged, should the end be refused)
                    continue
                self.told[aid] = up
                if held:
                    self.deferred[aid] = up
                else:
                    out += self._change(aid, up, now_s, t)
        return out

    def judge(self, now_s: float, t: float) -> list[Event]:
        """A stall is over: agents that are down now (and were up) are losses; ones that flapped are not."""
        out: list[Event] = []
        for aid, up in sorted(self.deferred.items()):
            if up != bool(self.alive[self.index[aid]]):
                out += self._change(aid, up, now_s, t)
        self.deferred = {}
        return out

    def _change(self, aid: int, up: bool, now_s: float, t: float) -> list[Event]:
        i = self.index[aid]
        before = self.alive_ids()
        if not up and self.alive[i]:
            if not self.burst_lost:
                self.burst_lost_at, self.burst_lost_t, self.burst_before = now_s, t, before
            self.burst_lost.append(aid)
        elif up and not self.alive[i] and aid in self.partitioned:
            if not self.burst_back:
                self.burst_back_at, self.burst_back_t = now_s, t
            self.burst_back.append(aid)
        was, seen = bool(self.alive[i]), bool(self.seen[i])
        self.alive[i] = up
        self.seen[i] |= up
        after = self.alive_ids()
        if up and not was and seen:  # (an agent's first token is no join)
            log.info("agent %d joined at t=%.2f", aid, t)
            return [Event(round(t, 9), EventKind.AGENT_JOINED, _g(before), _g(after), agent=aid,
                          wall_unix=self._wall(now_s))]
        if not up and was:
            log.warning("agent %d lost at t=%.2f", aid, t)
            return [Event(round(t, 9), EventKind.AGENT_LOST, _g(before), _g(after), agent=aid,
                          wall_unix=self._wall(now_s))]
        return []

    def network(self, now_s: float) -> list[Event]:
        """Several agents lost together while others stay is the swarm's network splitting: a split (cause
        "network"); their return, a merge. Single losses stay agent_lost / agent_joined only."""
        alive, out = self.alive_ids(), []
        if self.burst_lost and now_s - self.burst_lost_at >= self.timing.burst_s:
            lost = sorted(a for a in set(self.burst_lost) if not self.alive[self.index[a]])
            if len(lost) >= 2 and alive:
                out.append(Event(round(self.burst_lost_t, 9), EventKind.SPLIT, _g(self.burst_before),
                                 _g(*sorted([alive, lost], key=lambda g: g[0])), cause="network",
                                 wall_unix=self._wall(now_s)))
                self.partitioned |= set(lost)
            self.burst_lost = []
        if self.burst_back and now_s - self.burst_back_at >= self.timing.burst_s:
            back = sorted(a for a in set(self.burst_back) if self.alive[self.index[a]])
            rest = [a for a in alive if a not in back]
            if back and rest:
                groups = _g(*sorted([rest, back], key=lambda g: g[0]))
                out.append(Event(round(self.burst_back_t, 9), EventKind.MERGE, groups, _g(alive), cause="network",
                                 wall_unix=self._wall(now_s)))
            self.partitioned -= set(back)
            self.burst_back = []
        return out
