"""Who an agent hears and waits for: its cells and its lockstep wait set, pure (no zenoh).

Beacons and obstacle sets are published under the cell of the sender's head point
(`swarm/<run>/cell/<cx>_<cy>/agent/<id>/...`, reconswarm/net/wire/cells.py). An agent listens to every cell
that meets the disk of radius reach + 3 V dt around its head point, V the scenario's speed bound:

- at tick k, as soon as its state is in (before its beacon and long before its command), it adds the cells
  around p_i(k) and publishes from the cell of p_i(k); once its command of tick k is out, it drops the cells
  only p_i(k-1) needed. A peer within reach of p_i(k+1) at k+1 lies within reach + V dt of p_i(k): its
  beacon of tick k+1 is published in a cell the agent already hears (zenoh keeps one session's order: the
  router has our subscription before our command, hence before anyone's state, hence beacon, of tick k+1).
- wait set at tick k (lockstep): the live peers (the node's rule: counted by the world's clock of k and not
  gone by their tokens) whose head point at k-1 (their beacon of tick k-1) lay within reach + 2 V dt of
  p_i(k-1). Anyone else cannot be within reach of p_i(k) at k, so it
  contributes exact zeros to the tick (repulsion beyond d_max,ij, no link beyond link range): leaving it out
  changes nothing, and the tick equals the in-process engine's row bit for bit. With no beacon of k-1 from a
  peer (tick 0, or a peer that joined again), the position it is known to be held at counts: its last
  beacon, else its start in the scenario.
  The beacons of k-1 in when the state of k comes are all the agent may ever hear: a peer puts its beacon of
  k-1 before its command of k-1, which the world waits for before it publishes any state of k, so through a
  client's one link to its router the beacon comes first, and the host hands samples over in the link's order
  (net/runtime/inbox.py `ordered`). A beacon of k-1 not in by then was put in a cell the agent does not hear.
- a beacon of tick k from a peer outside the wait set but within reach of p_i(k) means the speed bound
  was violated (or a beacon of k-1 came after the state of k: samples from peers that reach the agent over
  links of their own, zenoh's peer mode, keep no order with the world's): whether it was in when the agent
  acted is a race, so lockstep is no longer deterministic and the node says so (`guessed_k`).
- until its first command an agent listens to every cell (it does not know yet where its robot is: a
  restarted agent catches up on every peer's cached obstacle set, and its first tick mid-mission waits
  for every live peer, as before the cells);
- the virtual-leader benchmark is centralised (every agent computes the leader from the union of every
  agent's set): in that mode the agent listens to every cell and waits for every live peer.
"""

from __future__ import annotations

import math
from collections.abc import Container, Iterable, Mapping
from collections.abc import Set as AbstractSet
from dataclasses import dataclass

from reconswarm.net.wire import wire
from reconswarm.net.wire.cells import Cell, CellGrid
from reconswarm.scenario.model import PlannerKind, Scenario

XY = tuple[float, float]


@dataclass(frozen=True)
class Cells:
    """Output of the node: publish from `home` from now on; listen to `listen` (None: every cell). What a new
    session must declare (`AgentNode.cells`) also says `warm`: the cells around our start, declared with every
    cell's subscription, so that our first command finds its cells declared."""

    home: Cell
    listen: frozenset[Cell] | None
    warm: frozenset[Cell] = frozenset()


class Neighbourhood:
    def __init__(self, s: Scenario, agent_id: int) -> None:
        self.id, self.dt_s = agent_id, s.meta.dt_s
        self.grid = CellGrid.for_scenario(s)
        self.everyone = s.planner.kind == PlannerKind.VIRTUAL_LEADER
        self.radius = {a.id: a.radius_m for a in s.agents}
        self.peers = frozenset(self.radius) - {agent_id}
        l_m, th = s.head_offsets, s.headings
        self.start: dict[int, XY] = {
            a.id: (float(a.start_m[0] + l_m[i] * math.cos(th[i])), float(a.start_m[1] + l_m[i] * math.sin(th[i])))
            for i, a in enumerate(s.agents)}
        self.joined: set[int] = set()  # peers whose token came back while we were acting, no beacon of a k-1 since
        self.near: dict[int, frozenset[int]] = {}  # tick -> peers that may matter at it (before the alive filter)
        self.own: dict[int, XY] = {}  # tick -> our head point
        # Every cell until our first command: a (re)started agent does not know where its robot is; so it
        # gets every peer's cached obstacle set and hears the beacons of the tick before its first.
        self.home: Cell = self.grid.cell_of(*self.start[agent_id])
        self.listen: frozenset[Cell] | None = None
        self._last_around: tuple[XY, frozenset[Cell], float] = ((math.inf, math.inf), frozenset(), -1.0)

    # ------------------------------------------------------------------------------------ membership

    def peer_joined(self, peer: int, acting: bool) -> None:
        """A peer's token appeared. Once we act, it is a peer (re)joining: its robot is held where it was."""
        if acting and peer != self.id:
            self.joined.add(peer)

    # -------------------------------------------------------------------------------------- cells

    def current(self) -> Cells:
        """What a new session must declare (every cell until our first command)."""
        return Cells(self.home, self.listen)

    def session_cells(self) -> Cells:
        """`current`, with the cells around our start (`warm`; none when we listen to every cell for good: the
        virtual leader's law)."""
        warm = frozenset() if self.everyone else self.grid.listen_cells(*self.start[self.id])
        return Cells(self.home, self.listen, warm)

    def on_state(self, k: int, p: XY) -> Cells | None:
        """Our state of tick k is in: add the cells around p (keep the old ones until our command is out) and
        publish from p's cell. None: nothing changes. Every cell until our first command, unless the mission
        starts now (k = 0): nobody has moved or shared anything yet, so our cells are all tick 0 can need."""
        self.own[k] = p
        home = self.grid.cell_of(*p)
        fresh_start = k == 0 and not self.everyone
        listen = None if self.listen is None and not fresh_start else (self.listen or frozenset()) | self._around(p)
        if home == self.home and listen == self.listen:
            return None
        self.home, self.listen = home, listen
        return Cells(home, listen)

    def after_command(self, k: int) -> Cells | None:
        """Our command of tick k is out: listen only around p_i(k)."""
        if self.everyone or k not in self.own:
            return None
        listen = self._around(self.own[k])
        if listen == self.listen:
            return None
        self.listen = listen
        return Cells(self.home, listen)

    def _around(self, p: XY) -> frozenset[Cell]:
        """The cells to listen to from p (computed again only once p leaves the margin around where they were)."""
        (x0, y0), cells, margin_m = self._last_around
        # (the same cells while p stays within the margin, kept 1 µm clear of rounding: `listen_cells` exactly)
        if p != (x0, y0) and not math.hypot(p[0] - x0, p[1] - y0) < margin_m - 1e-6:
            cells = self.grid.listen_cells(*p)
            self._last_around = (p, cells, self.grid.listen_margin_m(*p))
        return cells

    # ----------------------------------------------------------------------------------- wait set

    def wait_set(self, k: int, alive: Iterable[int], prev: Mapping[int, wire.Beacon],
                 last_seen: Mapping[int, wire.Beacon]) -> frozenset[int]:
        """The live peers tick k waits for (fixed at its first call for k, then filtered by `alive`).
        prev: the peers' beacons of tick k-1."""
        if self.everyone:
            return frozenset(alive) - {self.id}
        near = self.near.get(k)
        if near is None:
            near = self._near(k, prev, last_seen)
            self.near[k] = near
        return near.intersection(alive)  # (near never holds us; for a set `alive`, as long as the smaller)

    def _near(self, k: int, prev: Mapping[int, wire.Beacon], last_seen: Mapping[int, wire.Beacon]) -> frozenset[int]:
        """Every peer of the scenario that may matter at k, alive or not: whom `alive` names may still grow
        after this is fixed (a token heard after the clock that counted it)."""
        if k > 0 and self.listen is None and (k - 1) not in self.own:  # our first tick, joining: we hear all
            return self.peers
        own = self.own.get(k - 1, self.own.get(k))
        if own is None:
            return frozenset()
        out = set()
        ox, oy, far = own[0], own[1], self.grid.matter_m  # (CellGrid.may_matter, inline)
        hypot, peers, joined = math.hypot, self.peers, self.joined
        # A peer with a beacon of k-1 is placed by it; one that joined again, by its beacons once its beacon of k-1
        # is in (not by any beacon of it: one of k may come before our state of k, and the wait set must not depend
        # on that order); after tick 0 nobody else can be near: not the whole swarm.
        for a, b in prev.items():
            if a in peers and hypot(ox - b.px, oy - b.py) <= far:
                out.add(a)
        back = [a for a in (peers if k == 0 else joined) if a in peers and a not in prev]
        joined.difference_update(prev.keys())
        for a in back:  # not moved since we knew it (its agent was away)
            seen = last_seen.get(a)
            pos = (seen.px, seen.py) if seen is not None else self.start.get(a)
            if pos is not None and hypot(ox - pos[0], oy - pos[1]) <= far:
                out.add(a)
        return frozenset(out)

    def near_now(self, p: XY, alive: Iterable[int], last_seen: Mapping[int, wire.Beacon]) -> set[int]:
        """Realtime: the live peers whose latest beacon may matter to us at p."""
        out = set()
        for a in alive:
            seen = last_seen.get(a)
            pos = (seen.px, seen.py) if seen is not None else self.start.get(a)  # never heard: held at its start
            if a != self.id and pos is not None and (self.everyone or self.grid.may_matter(p, pos)):
                out.add(a)
        return out

    @staticmethod
    def heard_lately(alive: Container[int], heard: dict[int, float], now: float, period_s: float,
                     silent_s: float) -> set[int]:
        """Realtime: the live peers heard within `silent_s` (the agent's policy: `realtime_peer_silent_s`) or 3
        periods of wall time. `heard` is in the order its times were set (the newest last) and holds every live
        peer (its token's time if nothing else): only the peers heard lately are read, not the whole swarm."""
        quiet = max(silent_s, 3.0 * period_s)
        out = set()
        for a in reversed(heard):  # (newest first)
            if now - heard[a] > quiet:
                break
            if a in alive:
                out.add(a)
        return out

    def intruder(self, k: int, b: wire.Beacon) -> bool:
        """A beacon of tick k from a peer we did not wait for at k, within reach of us at k: the speed bound
        was violated (whether it was in when we acted is a race)."""
        near, own = self.near.get(k), self.own.get(k)  # (called for most beacons that arrive: nothing built)
        if self.everyone or near is None or own is None or b.id in near:
            return False
        return (b.px - own[0]) ** 2 + (b.py - own[1]) ** 2 <= self.grid.reach_m ** 2

    def intruders(self, k: int, fresh: Mapping[int, wire.Beacon]) -> list[wire.Beacon]:
        """The intruders among tick k's beacons `fresh` (by peer), in id order, reading only the peers we did not
        wait for."""
        near, own = self.near.get(k), self.own.get(k)
        if self.everyone or near is None or own is None:
            return []
        ox, oy, reach2 = own[0], own[1], self.grid.reach_m ** 2  # (`intruder`, inline: every agent, every tick)
        return [b for a in sorted(fresh.keys() - near) if ((b := fresh[a]).px - ox) ** 2 + (b.py - oy) ** 2 <= reach2]

    def also_heard(self, alive: set[int], prev: Mapping[int, wire.Beacon], fresh: Mapping[int, wire.Beacon],
                   waited: AbstractSet[int]) -> int:
        """How many beacons of this tick will come from peers we do not wait for (they published the tick
        before in a cell we listen to): the runtime sleeps until they are in too, instead of waking early."""
        cells, cell_of = self.listen, self.grid.cell_of
        return sum(1 for a in prev.keys() - waited - fresh.keys()
                   if a in alive and (cells is None or cell_of(prev[a].px, prev[a].py) in cells))

    def unexpected(self, b: wire.Beacon) -> str:
        """Why an intruder's beacon makes the tick a guess (for the log)."""
        v = self.grid.step_m / self.dt_s
        return (f"agent {b.id} within reach at tick {b.k} though not expected (faster than the speed bound "
                f"{v:g} m/s, or its beacon of the tick before came late)")

    def audible(self, p: XY, b: wire.Beacon) -> bool:
        """Is a peer's beacon at b still in a cell we listen to from p (else its position is stale)?"""
        return self.everyone or self.grid.cell_of(b.px, b.py) in self._around(p)

    def prune(self, k: int) -> None:
        for store in (self.near, self.own):
            for kk in [x for x in store if x < k - 4]:
                del store[kk]
