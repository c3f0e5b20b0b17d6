"""An agent process's session: one or many agents (`reconswarm agent --ids 1-5,9`) on one zenoh session.

Zenoh's guidance is one session per process, shared by its nodes (as rmw_zenoh gives every ROS 2 node of a
process one session). The host holds the session's subscriptions and hands each sample to the agents it
is for, through one inbox and one loop that steps every hosted node (agent/node.py) with the wall time:

- shared by all hosted agents: the clock, liveliness (every token, with history), and each cell's beacon
  batches and obstacle sets, declared while at least one hosted agent listens to that cell (agent/listening.py)
  and handed to those that do;
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

Co-hosted agents hear each other in the process (agent/loopback.py); the subscriptions take remote samples only.
A node is stepped when it has input, a deadline, or every `agent_poll_s` (its timers).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Sequence
from typing import Any

import zenoh

from agent.beacons import BeaconOut, handover_cell, handover_label, take_batch
from agent.brain import Plan, commands
from agent.hosted import OWN, PASSED, PEER_MESSAGES, Decoded, HostedAgent, decode_sample
from agent.listening import CellListening
from agent.loopback import Loopback
from agent.messages import Input, Law, Reconnect
from agent.neighbours import Cells
from agent.robot_io import HostKeys, KeysRobot, take_states
from reconswarm.net.node import Exit, Invalid
from reconswarm.net.runtime import trace
from reconswarm.net.runtime.inbox import Inbox, Item, Tag
from reconswarm.net.runtime.lifecycle import Stopper
from reconswarm.net.runtime.runtime import Runtime
from reconswarm.net.trust.admission import Intrusion
from reconswarm.net.wire import wire
from reconswarm.net.wire.batch import BeaconBatch
from reconswarm.net.wire.cells import Cell
from reconswarm.net.wire.hostwire import StateBatch
from reconswarm.net.wire.keys import Keys

log = logging.getLogger("reconswarm.agent")
RECONNECT = -1  # AgentHost.run's answer when the session must be opened again
# The subscription a sample came through (its tag in the inbox): ALL, ("own", agent id), ("cell", cell or None),
# robot_io.STATES; and ("local", agent id) for what a co-hosted agent published (agent/loopback.py)
ALL: Tag = ("all", None)  # for every hosted agent: the clock, liveliness
ALONE = (Invalid, *OWN)  # what each agent's own link takes for itself (a malformed sample, a state or scan)


class AgentHost:
    """The session's subscriptions around the hosted agents' links; `run` is the process's loop."""

    def __init__(self, session: zenoh.Session, keys: Keys, links: dict[int, HostedAgent],
                 inbox: Inbox) -> None:
        self.z, self.keys, self.links, self.inbox = session, keys, links, inbox
        self.active = dict(links)  # the agents still running (one that exited leaves this)
        self.source = str(session.info.zid())  # the source of what co-hosted agents hand each other
        self.loop = Loopback(self.source, len(links) > 1)  # what they publish, handed over (agent/loopback.py)
        self.plans: list[tuple[int, Plan]] = []  # the hosted agents' plans of this round, for `answers`
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
        warm: frozenset[Cell] = frozenset().union(*(c.warm for c in start.values()))
        self.cells = CellListening(session, keys, inbox, warm, self.active)  # (agent/listening.py)
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
        """Agent aid listens to c.listen from now on (agent/listening.py); the newest set of each agent publishing in
        the cells it did not hear yet is replayed to it (what its own advanced subscriber's history would bring)."""
        gained = self.cells.listen(aid, c.listen)
        if gained is not None:
            self.loop.newly_heard(aid, gained)

    def _others(self, sender: int, key: str) -> list[int]:
        """Whom a co-hosted agent's beacon (under its handover label) or set (under its key) is for: the running
        agents that listen to its cell, but not its sender."""
        cell = handover_cell(key)
        return [a for a in self.cells.listeners(self.cells.cell_of(key) if cell is None else cell) if a != sender]

    # ---------------------------------------------------------------------------------------- input

    def route(self, items: Sequence[tuple[Tag, Item]], now_s: float = 0.0) -> dict[int, list[Input]]:
        """Each hosted agent's batch: every sample decoded once, taken by each agent it is for. A beacon or set is
        for the agents that listen to the cell it was published in, whichever of the host's subscriptions it
        came through (one just replaced, or every cell's), once."""
        batches: dict[int, list[Input]] = {aid: [] for aid in self.active}
        replay, local = self.loop.take()
        for aid, tag, item in replay:
            self._deliver(tag, item, batches, aid)
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
            cell = self.cells.cell_of(key)
            who = self.cells.listeners(tag[1] if cell is None else cell)
        if only is not None:
            who = [a for a in who if a == only]
        if not who:
            return
        # A co-hosted agent's own beacon or set, handed over in the process: ours, believed without admission
        # (the tag is the host's own: no sample from zenoh carries it, whatever source it is stamped with).
        cohosted = tag[0] == "local"
        if source == self.source and not cohosted and self.loop.echo(key, payload):
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
        elif (isinstance(m, wire.ObstacleSet) and only is None and m.id in self.known
              and self.cells.cell_of(key) is not None):
            self.loop.admitted(m.id, tag, item)

    def _refuse(self, who: list[int], bad: Intrusion) -> None:
        """A sample admission refused: counted (and logged) by each agent it was for."""
        now = time.monotonic()
        for aid in who:
            self.active[aid].gate.refuse(bad, now)

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
        return self.loop.pending(self._others)

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
        self.cells.changed()
        if code.code != 0 and self.active:  # it stops; its co-hosted agents go on
            self.cells.forget(aid)
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
        if put is not None and isinstance(out, wire.Beacon | wire.ObstacleSet):
            self.loop.published(aid, put, out, now_s)
        return False

    def _flush(self) -> None:
        """The round's beacons, if any are left to put (called before each command: once a round they are)."""
        if self.out.pending:
            self.out.flush({link.home for link in self.active.values() if link.home is not None})

    def close(self) -> None:
        self._flush()
        self.out.close()
        if self.robots is not None:
            self.robots.close()
        for link in self.links.values():
            link.close()
        self.token.undeclare()
        self.cells.close()
        for sub in self.subs:
            sub.undeclare()
