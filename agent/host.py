"""An agent process's session: one or many agents (`reconswarm agent --ids 1-5,9`) on one zenoh session.

Zenoh's guidance is one session per process, shared by its nodes (as rmw_zenoh gives every ROS 2 node of a
process one session). The host holds the session's subscriptions and hands each sample to the agents it
is for, through one inbox and one loop that steps every hosted node (agent/node.py) with the wall time:

- shared by all hosted agents: the clock, liveliness (every token, with history), and each cell's beacon
  batches and obstacle sets (advanced subscriber: publishers' cached sets), declared while at least one hosted
  agent listens to that cell (agent/neighbours.py) and handed to those that do; an agent that starts
  listening to a cell the host already hears gets the newest set of each publisher there, from the host's copy;
- the hosted agents' states: one message per tick for all of them (urgent: it starts a tick), taken apart once
  (agent/robot_io.py `HostKeys`, `take_states`); in ROS 2 mode each agent's odometry and its scan;
- a sample is decoded and admitted once, whatever number of hosted agents it is for: each beacon of a peer
  host's batch, a set and the clock are judged by the host's one admission (the hosted agents' gates share it)
  and appended to the batch of each agent that listens (a refusal is counted by each of them); what concerns
  one agent alone (its state, a sample on its own key, a malformed one) goes through its own link;
- the law: the plans of one tick that the hosted agents' nodes returned in a round are computed in one call of
  `law` (each row the same bit for bit as the agent's alone) and each node takes its command back (`Law`);
- beacons go out as one message per cell and round (agent/beacons.py), put before any command of the round; the
  round's commands as one message (`HostKeys.flush`) once the round is over;
- the host's own liveliness token `alive/host/<hid>/<members>` (declared before its agents' own tokens) tells the
  world which agents it speaks for (simworld/hosts.py).

Co-hosted agents hear each other in the process: a beacon or set one of them publishes is handed to the others
that listen to its cell, at once (a beacon as the message itself; a set as its bytes with the session as
source); the subscriptions take remote samples only. A node is stepped when it has input, a deadline, or every
`agent_poll_s` (its timers).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections import deque
from collections.abc import Sequence
from typing import Any

import zenoh
from zenoh import ext

from agent.beacons import BeaconOut, handover_cell, handover_label, take_batch
from agent.brain import Plan, commands
from agent.hosted import OWN, PASSED, PEER_MESSAGES, Decoded, HostedAgent, decode_sample
from agent.messages import Input, Law, Reconnect
from agent.neighbours import Cells
from agent.robot_io import HostKeys, KeysRobot, take_states
from agent.tagged_inbox import ALL, Tag, TaggedInbox
from reconswarm.net.node import Exit, Invalid
from reconswarm.net.runtime import trace
from reconswarm.net.runtime.inbox import Item
from reconswarm.net.runtime.lifecycle import Stopper
from reconswarm.net.runtime.runtime import Runtime
from reconswarm.net.trust.admission import Intrusion
from reconswarm.net.wire import wire
from reconswarm.net.wire.batch import BeaconBatch
from reconswarm.net.wire.cells import Cell
from reconswarm.net.wire.hostwire import StateBatch
from reconswarm.net.wire.keys import Keys, WireError

log = logging.getLogger("reconswarm.agent")
RECONNECT = -1  # AgentHost.run's answer when the session must be opened again
ALONE = (Invalid, *OWN)  # what each agent's own link takes for itself (a malformed sample, a state or scan)
ECHOES = 4  # a hosted agent's own sets recognised when they come back from its cache: its newest puts


class AgentHost:
    """The session's subscriptions around the hosted agents' links; `run` is the process's loop."""

    def __init__(self, session: zenoh.Session, keys: Keys, links: dict[int, HostedAgent],
                 inbox: TaggedInbox) -> None:
        self.z, self.keys, self.links, self.inbox = session, keys, links, inbox
        self.active = dict(links)  # the agents still running (one that exited leaves this)
        self.locality = zenoh.Locality.REMOTE  # (co-hosted agents' samples are handed over in the process)
        self.source = str(session.info.zid())  # the source of what co-hosted agents hand each other
        # What co-hosted agents published since the last round: a beacon with the message it was put from (the bytes
        # decode to it: nothing to decode again, 200 a tick in a host of 200), a set as its bytes (decoded once).
        self.local: list[tuple[Tag, Item, wire.Beacon | None]] = []
        self.listening: dict[int, frozenset[Cell] | None] = {}  # agent -> the cells it listens to (None: all)
        self.by_cell: dict[Cell | None, set[int]] = {}  # cell -> the agents listening to it (None: to all)
        self._heard_by: dict[Cell | None, list[int]] = {}  # cell -> `_listeners` (until listening or `active` change)
        self.cell_subs: dict[Cell | None, tuple[Any, Any]] = {}  # the host's subscriptions (None: every cell)
        self.plans: list[tuple[int, Plan]] = []  # the hosted agents' plans of this round, for `answers`
        self.sets: dict[int, tuple[Tag, Item]] = {}  # agent -> its newest obstacle set heard (its cell in its key)
        # Each hosted agent's newest obstacle sets put (key, payload), the newest in its publisher's cache: what our
        # own subscribers' history queries get back (zenoh does not filter a query's replies by the allowed origin);
        # the few before it too, for a reply that left the cache before the agent's next put.
        self.cached: dict[int, deque[tuple[str, bytes]]] = {}
        self.replay: list[tuple[int, Tag, Item]] = []  # (agent, tag, obstacle set) for that agent alone (replayed)
        self._alive: tuple[int, ...] = ()  # the newest clock's live agents (one tuple while they stay the same)
        first = next(iter(links.values()))
        self.known = {a.id for a in first.node.s.agents}
        self.out = BeaconOut(session, keys, min(links))  # our beacons: one batch per cell and round (agent/beacons.py)
        # The hosted agents' gates share one admission (agent/process.py): this one judges each sample once.
        self.gate = first.gate
        # The cells around the hosted agents' starts, declared with every cell's subscription: an agent that listens
        # to every cell until its first command then finds its own cells declared (not declared all at once, on
        # the mission's first tick, when every hosted agent commands for the first time).
        start = {aid: link.node.cells() for aid, link in links.items()}  # (what each node says it needs now)
        self.warm: frozenset[Cell] = frozenset().union(*(c.warm for c in start.values()))
        z, k = session, keys
        self.subs: list[Any] = []
        for aid, link in links.items():
            self.listen(aid, start[aid])
            # Our state starts a tick: it wakes the loop at once; the rest wakes it only once the nodes' count of
            # what they still need is in.
            self.subs += [z.declare_subscriber(key, inbox.handler(("own", aid), urgent=urgent))
                          for key, urgent in link.robot.own_keys(k)]
        # On the project's keys, our agents' robots speak through one subscription and one publisher for all.
        keyed = [link.robot for link in links.values() if isinstance(link.robot, KeysRobot)]
        self.robots = HostKeys(session, keys, tuple(links)) if keyed else None
        for robot in keyed:
            robot.out = self.robots
        if self.robots is not None:
            self.subs.append(self.robots.subscribe(inbox.handler))
        self.subs += [z.declare_subscriber(k.clock, inbox.handler(ALL)),
                      z.liveliness().declare_subscriber(k.alive_all, inbox.handler(ALL), history=True)]
        # Declared last, ours first: it names whom we speak for; an agent's token tells the world it is ready.
        self.token = z.liveliness().declare_token(k.alive_host(tuple(links)))
        for link in links.values():
            link.announce()

    # ------------------------------------------------------------------------------------ listening

    def listen(self, aid: int, c: Cells) -> None:
        """Agent aid listens to c.listen from now on: cells new to the host are declared before the ones nobody
        listens to any more go; the newest set of each agent publishing in the cells it did not hear yet is
        replayed to it (what its own advanced subscriber's history would have brought)."""
        old = self.listening.get(aid, frozenset())
        if aid in self.listening and old == c.listen:
            return
        self.listening[aid] = c.listen
        self._heard_by.clear()
        for cell in {None} if old is None else old:  # (the index: who listens to a cell; None: to every cell)
            self.by_cell.get(cell, set()).discard(aid)
        for cell in {None} if c.listen is None else c.listen:
            self.by_cell.setdefault(cell, set()).add(aid)
        self.replay += [(aid, tag, item) for tag, item in self.sets.values()
                         if self._hears(c.listen, self._cell(item[0])) and not self._hears(old, self._cell(item[0]))]
        want: set[Cell | None] = {cell for cell, heard_by in self.by_cell.items() if heard_by}  # (every listened cell)
        if None in want:
            want |= self.warm
        for cell in want - self.cell_subs.keys():
            tag, k = ("cell", cell), self.keys
            self.cell_subs[cell] = (
                self.z.declare_subscriber(k.host_beacons(cell, None), self.inbox.handler(tag, rows=True),
                                          allowed_origin=self.locality),
                ext.declare_advanced_subscriber(self.z, k.cell_agents(cell, "obstacles"), self.inbox.handler(tag),
                                                allowed_origin=self.locality,
                                                history=ext.HistoryConfig(detect_late_publishers=True)))
        for cell in self.cell_subs.keys() - want:
            for sub in self.cell_subs.pop(cell):
                sub.undeclare()

    def _listeners(self, cell: Cell | None) -> list[int]:
        """The running agents that listen to `cell` (a valid one; None: nobody but those listening to every cell),
        in id order."""
        heard_by = self._heard_by.get(cell)
        if heard_by is None:
            got = self.by_cell.get(cell, set()) if cell is not None else set()
            heard_by = self._heard_by[cell] = sorted(a for a in got | self.by_cell.get(None, set()) if a in self.active)
        return heard_by

    def _others(self, sender: int, key: str) -> list[int]:
        """Whom a co-hosted agent's beacon (under its handover label) or set (under its key) is for: the running
        agents that listen to its cell, but not its sender."""
        cell = handover_cell(key)
        return [a for a in self._listeners(self._cell(key) if cell is None else cell) if a != sender]

    @staticmethod
    def _hears(listen: frozenset[Cell] | None, cell: Cell | None) -> bool:
        return listen is None or cell in listen

    def _cell(self, key: str) -> Cell | None:
        """The cell a beacon or obstacle set was published in (None: a key without a valid one)."""
        try:
            return self.keys.parsed(key).cell
        except WireError:
            return None

    # ---------------------------------------------------------------------------------------- input

    def route(self, items: Sequence[tuple[Tag, Item]], now_s: float = 0.0) -> dict[int, list[Input]]:
        """Each hosted agent's batch: every sample decoded once, taken by each agent it is for. A beacon or set is
        for the agents that listen to the cell it was published in, whichever of the host's subscriptions it
        came through (one just replaced, or every cell's), once."""
        batches: dict[int, list[Input]] = {aid: [] for aid in self.active}
        pending, self.replay = self.replay, []
        for aid, tag, item in pending:
            self._deliver(tag, item, batches, aid)
        local, self.local = self.local, []
        for tag, item, sent in local:
            self._deliver(tag, item, batches, None, sent)
        seen: set[tuple[str, bytes, str]] = set()
        for tag, item in items:
            if tag[0] == "cell":
                once = (item[0], item[1], item[3])
                if once in seen:
                    continue
                seen.add(once)
            self._deliver(tag, item, batches, None)
        for aid, link in self.active.items():
            batches[aid] += link.robot.dropped()
        return batches

    def _deliver(self, tag: Tag, item: Item, batches: dict[int, list[Input]], only: int | None,
                 sent: wire.Beacon | None = None) -> None:
        """Hand one sample to the agents it is for (`only`: to that one alone); `sent`: the co-hosted agent's beacon
        the sample was put from (its bytes decode to it: not decoded again)."""
        key, payload, kind, source, at_s = item
        if tag[0] == "states":
            take_states(decode_sample(self.keys, key, payload, kind), key, source, at_s, self.active, self.links,
                        self.gate, batches)
            return
        if tag[0] == "own":
            link = self.active.get(tag[1])
            mine = None if link is None else link.decode(key, payload, kind, source)
            if mine is not None:
                batches[tag[1]].append(mine)
                if isinstance(mine, wire.State):
                    trace.mark(trace.Mark.STATE_IN, mine.k, mine.id, at_s)
            return
        if tag == ALL:
            who = list(self.active)
        elif tag[0] == "local":  # a co-hosted agent's: for the others that hear its cell
            who = self._others(tag[1], key)
        else:  # (a key with no valid cell: those the subscription it came through was for, to count it)
            cell = self._cell(key)
            who = self._listeners(tag[1] if cell is None else cell)
        if only is not None:
            who = [a for a in who if a == only]
        if not who:
            return
        # A co-hosted agent's own beacon or set, handed over in the process: ours, believed without admission
        # (the tag is the host's own: no sample from zenoh carries it, whatever source it is stamped with).
        cohosted = tag[0] == "local"
        if source == self.source and not cohosted and self._echo(key, payload):
            return  # our own set from our publisher's cache: the others had it at its put (or have it replayed)
        if key.endswith("/obstacles") and not cohosted:  # (its size, before decoding: once for all)
            too_big = self.gate.adm.check_set_size(len(payload), source, key)
            if too_big is not None:
                self._refuse(who, too_big)
                return
        m: Decoded = sent if sent is not None else decode_sample(self.keys, key, payload, kind)
        if isinstance(m, wire.Clock):  # (the live agents of the clock before, if the same: one tuple, known at once)
            if m.alive == self._alive:
                m = dataclasses.replace(m, alive=self._alive)
            self._alive = m.alive
        if isinstance(m, StateBatch):  # (only on our states' key: not a cell's or everyone's)
            return
        if isinstance(m, BeaconBatch):
            take_batch(m, key, source, who, batches, at_s, self.active, self.gate, len(self.known))
            return
        if cohosted or m is None or isinstance(m, PASSED):
            if m is not None:
                for aid in who:
                    batches[aid].append(m)
            return
        # In the name of an agent running in this process, from another session: forged (ours never come that way).
        forged = m.id if isinstance(m, PEER_MESSAGES) and m.id in self.active else None
        if forged is not None or isinstance(m, ALONE):  # (rare: each agent's own link says what it is)
            for aid in who:
                link = self.active[aid]
                if forged is not None and aid != forged:  # (its own link counts one on its own key as invalid)
                    link.refuse_cohosted(forged, key, source)
                elif (got := link.take(m, key, source)) is not None:
                    batches[aid].append(got)
            return
        # A peer's beacon or set, the clock: judged once for every agent it is for (their gates share one admission)
        bad = self.gate.check(m, source, key, time.monotonic())
        if bad is not None:
            self._refuse(who, bad)
            return
        for aid in who:
            batches[aid].append(m)
        if isinstance(m, wire.Beacon):
            trace.mark(trace.Mark.BEACON_IN, m.k, m.id, at_s)
        elif isinstance(m, wire.Clock):  # (each gate's newest clock: the first_t of what it refuses)
            for aid in who:
                self.active[aid].gate.clocked(m)
        # Kept for an agent that starts listening to its cell later: a set admitted (a co-hosted agent's own is kept
        # by `act`), never one that was refused (it would stand in for the genuine one).
        elif isinstance(m, wire.ObstacleSet) and only is None and m.id in self.known and self._cell(key) is not None:
            self.sets[m.id] = (tag, item)

    def _refuse(self, who: list[int], bad: Intrusion) -> None:
        """A sample admission refused: counted (and logged) by each agent it was for."""
        now = time.monotonic()
        for aid in who:
            self.active[aid].gate.refuse(bad, now)

    def _echo(self, key: str, payload: bytes) -> bool:
        """A set a hosted agent put (one of its ECHOES newest), as its publisher's cache held it: a cell subscription
        declared after the put (an agent that starts listening to the publisher's cell) queries that cache, ours
        included, and the reply may leave before the agent's next put and arrive after it. Anything else with our
        session's id as its source (anyone can stamp it) goes through admission as before."""
        return any(k == key and p == payload for puts in self.cached.values() for k, p in puts)

    # ------------------------------------------------------------------------------ the runtime's port

    def run(self, stop: Stopper, who: str) -> int:
        """Feed the nodes (net/runtime/runtime.py) until all exited (the largest exit code) or one asks for a new
        session (RECONNECT); a signal stops each (0)."""
        nodes = {aid: link.node for aid, link in self.links.items()}
        poll_s = min(n.timing.agent_poll_s for n in nodes.values())
        rt = Runtime(self.z, who, stop, self.inbox, poll_s)
        exits = rt.run(nodes, self, started=lambda: any(n.started for n in nodes.values()), cohosting=self)
        if rt.interrupted:  # (plans of the interrupted round: their commands, before this session goes)
            now = time.monotonic()
            for aid, inputs in self.answers(now).items():
                for out in nodes[aid].step(inputs, now):
                    if not isinstance(out, Exit | Reconnect):
                        self.act(aid, out, now)
            self.answers(now)
        return RECONNECT if rt.interrupted else max((e.code for e in exits.values()), default=0)

    def pending(self) -> dict[int, int]:
        """How many inputs each hosted agent's next batch holds already: what co-hosted agents published for it
        (their beacons and sets in its cells), the sets replayed to it."""
        held: dict[int, int] = {}
        for aid, _tag, _item in self.replay:
            held[aid] = held.get(aid, 0) + 1
        for tag, item, _sent in self.local:
            for aid in self._others(tag[1], item[0]):
                held[aid] = held.get(aid, 0) + 1
        return held

    def answers(self, now_s: float) -> dict[int, list[Input]]:
        """The law of every plan the hosted agents returned in this round, computed at once for those of one tick
        (agent/brain.py `commands`: each row the same bit for bit as the agent's alone)."""
        self._flush()  # (the round's beacons, before any command of it)
        by_tick: dict[int, list[tuple[int, Plan]]] = {}
        for aid, plan in self.plans:
            by_tick.setdefault(plan.k, []).append((aid, plan))
        self.plans = []
        out: dict[int, list[Input]] = {}
        for k, plans in by_tick.items():
            for (aid, _p), (v, w) in zip(plans, commands([p for _aid, p in plans]), strict=True):
                out[aid] = [Law(k, v, w)]
        if not out and self.robots is not None:  # (the round is over: its commands, in one message)
            self.robots.flush()
        return out

    def idle(self, who: int, now_s: float) -> None:
        self.links[who].report()

    def exited(self, aid: int, code: Exit, now_s: float) -> None:
        link = self.links[aid]
        link.report(final=True)
        del self.active[aid]
        self._heard_by.clear()
        if code.code != 0 and self.active:  # it stops; its co-hosted agents go on
            self.listen(aid, Cells(link.home or (0, 0), frozenset()))
            self.listening.pop(aid)
            link.close()

    def act(self, aid: int, out: Any, now_s: float) -> bool:
        if isinstance(out, Plan):  # (its law, with the other plans of this round: `answers`)
            self.plans.append((aid, out))
            return False
        if isinstance(out, Reconnect):
            return True
        if isinstance(out, Cells):
            self.listen(aid, out)
        if isinstance(out, wire.Beacon):  # (put with the round's others: `_flush`)
            home = self.links[aid].home
            assert home is not None
            self.out.add(home, out)
            put: tuple[str, bytes] | None = (handover_label(home, aid), b"")  # (its label in the process)
        else:
            if isinstance(out, wire.Cmd):
                self._flush()
            put = self.links[aid].publish(out)
        if put is not None and isinstance(out, wire.ObstacleSet):
            self.cached.setdefault(aid, deque(maxlen=ECHOES)).append(put)
        if put is not None and len(self.links) > 1:
            item = (put[0], put[1], "PUT", self.source, now_s)
            self.local.append((("local", aid), item, out if isinstance(out, wire.Beacon) else None))
            if isinstance(out, wire.ObstacleSet):
                self.sets[aid] = (("local", aid), item)  # (for an agent that starts listening to its cell later)
        return False

    def _flush(self) -> None:
        self.out.flush({link.home for link in self.active.values() if link.home is not None})

    def close(self) -> None:
        self._flush()
        self.out.close()
        if self.robots is not None:
            self.robots.close()
        for link in self.links.values():
            link.close()
        self.token.undeclare()
        for subs in self.cell_subs.values():
            for sub in subs:
                sub.undeclare()
        for sub in self.subs:
            sub.undeclare()
