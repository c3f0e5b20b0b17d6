"""Lockstep, as an agent's node keeps it (agent/node.py `pace`): the world holds each tick until every command of
the tick before is in, so tick k is acted on with exactly the data the in-process engine's tick k uses, and the
run equals `reconswarm sim` pose for pose.

At tick k the node waits for its state (its scan inside), announces its beacon (with the revision of its obstacle
set at k-1) at once, then waits for the beacons of the live agents that may matter at k (agent/neighbours.py: the
cells it listens to and its wait set; every live agent for the virtual leader) and the obstacle sets of those
within link range at k (all for the virtual leader), and plans. A beacon not in after `beacon_again_s` goes out
again (backing off; the obstacle set once). Each way on without some of a tick's data is a guess, which the node
says (`guessed_k`: the run is no longer deterministic from there): the tick's clock never came, a peer alive but
silent, the wait given up, a beacon that came after the tick was acted on, the router link lost mid-tick.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from collections.abc import Set as AbstractSet

import numpy as np

from agent.brain import Body
from agent.pace import Paced
from reconswarm.net.trust.membership import silent
from reconswarm.net.wire import wire


class Lockstep:
    """Every tick in turn, each once all its data is in."""

    holds_awaiting = True  # `AgentNode.awaiting`'s count stands until the next step (only a silence lowers it)

    @staticmethod
    def next_tick(node: Paced) -> int:
        """The tick to act on next: the one after our last, once its state is in."""
        newest = max(node.h.states, default=-1)
        return node.k + 1 if node.k >= 0 and (node.k + 1) in node.h.states else newest

    def advance(self, node: Paced, now: float) -> None:
        """Act on every tick whose data is in, in turn (until a plan is out)."""
        while node.h.states:
            k = self.next_tick(node)
            if k <= node.k or not ready(node, k, now):
                return
            node.act(k, now)
            if node.planning >= 0:
                return

    @staticmethod
    def expected(node: Paced, k: int, clock: wire.Clock | None) -> AbstractSet[int]:
        """The live peers tick k waits for: those that may matter (agent/neighbours.py) and the world counts alive
        at k (kept until the clock or a token changes)."""
        p = (node.h.states[k].px, node.h.states[k].py)
        key = (k, node.h.tokens, clock is None)
        if (got := node.waited.get(key)) is None or got[0] is not clock:
            node.nb.own.setdefault(k, p)
            prev = node.h.beacons.get(k - 1, {})
            got = node.waited[key] = (clock, node.nb.wait_set(k, node.h.living(clock), prev, node.h.last_seen))
        return got[1]

    @staticmethod
    def more_needed(node: Paced, k: int, clock: wire.Clock | None, fresh: Mapping[int, wire.Beacon],
                    waited: AbstractSet[int]) -> int:
        """What else tick k waits for at least: beacons of peers heard at k-1 that may come in, its clock, the
        obstacle sets its linked peers announced."""
        need = node.nb.also_heard(node.h.alive, node.h.beacons.get(k - 1, {}), fresh, waited) + (clock is None)
        if node.linked[0] == k:
            need += sum(1 for a, rev in node.linked[1].items() if rev and rev not in node.sets.get(a, ()))
        return need

    def wanted(self, node: Paced, k: int, p: tuple[float, float]) -> AbstractSet[int]:
        """The live peers tick k plans with at their latest beacon when their beacon of k lacks: those it waited for."""
        return self.expected(node, k, None)

    @staticmethod
    def on_state(node: Paced, now: float) -> None:
        """Our state came: nothing to schedule (the data, not a deadline, lets a tick go)."""

    @staticmethod
    def quiet(node: Paced, now: float) -> bool:
        """The world stalls: its token is gone, or it said nothing for `world_quiet_s`."""
        return node.world_gone or now - node.world_at > node.timing.world_quiet_s

    @staticmethod
    def loses_in_flight(node: Paced) -> bool:
        """Our router link went mid-mission: what was in flight to us is lost (the next tick is a guess)."""
        return node.started and not node.ended

    @staticmethod
    def check_late(node: Paced, k: int) -> None:
        """Before tick k goes: a beacon of k that came from an agent it did not wait for, or the link lost meanwhile,
        makes it a guess (the link first: their cause)."""
        if node.guess:
            return
        late = node.nb.intruders(k, node.h.beacons.get(k, {}))
        gone = "our router link went: what was in flight to us (a beacon, a set) is lost" if node.link_lost else ""
        node.guess = gone or (node.nb.unexpected(late[0]) if late else "")

    @staticmethod
    def linked_sets(node: Paced, k: int, p: np.ndarray, peers: Sequence[Body], lost: Sequence[Body]) -> dict[
            int, int]:
        """The sets tick k merges: exactly the linked peers' sets at k-1, as their beacons at k announce."""
        if node.linked[0] != k:  # (the wait gave up before all beacons came)
            node.link(k, p)
        return node.linked[1]

    @staticmethod
    def swarm_revisions(node: Paced, k: int) -> dict[int, int]:
        """The virtual leader's: every peer's set at k-1, as announced at k."""
        return {a: b.rev for a, b in node.h.beacons.get(k, {}).items()}

    @staticmethod
    def living_at(node: Paced, k: int) -> AbstractSet[int]:
        """The peers alive at tick k (whose stale beacons are kept)."""
        return node.h.living(node.h.clocks.get(k))


LOCKSTEP = Lockstep()


def ready(node: Paced, k: int, now: float) -> bool:
    """True once everything tick k needs is in (or the wait timed out)."""
    t = node.timing
    st, clock = node.h.states.get(k), node.h.clocks.get(k)
    if st is None:
        return False
    # Our beacon goes out as soon as our state is in: the peers wait for it (it does not need the clock).
    if node.beacon_sent < k or now > node.beacon_again:  # (again if peers may have lost it)
        if node.beacon_sent < k:
            node.move(k, st)
        node.out.append(node.beacon(st))
        if node.beacon_sent < k:
            node.wait_since, node.again_n = now, 0
        else:
            node.again_n += 1
            if node.again_n == 1 and node.brain.rev:  # stuck: peers may have lost our obstacle set too
                node.out.append(node.obstacle_set(k))
        node.beacon_sent = k
        # Backing off (0.5, 1, 2 s, ...), the set only once: re-sent every 0.5 s it flooded a stuck N = 64.
        node.beacon_again = now + t.beacon_again_s * 2 ** node.again_n
    # Each way on without some of the tick's data is a guess: the command may differ from the in-process
    # engine's from here on, so the node says so (`guessed_k` in its reports, then the record's summary).
    node.guess, quiet = "", node.quiet(now)  # (none while the world stalls: a peer may lack only its state)
    if clock is None:
        # The tick's clock may have been lost (an outage): after a while, go on with the newest clock's agents.
        first = node.h.state_at.setdefault(k, now)
        if now - first < t.agent_wait_timeout_s or not node.h.clocks or quiet:
            return False
        clock = node.h.clocks[max(node.h.clocks)]
        node.guess = "the tick's clock never came"
    if node.wait_since is not None and now - node.wait_since > t.agent_wait_timeout_s and not quiet:
        node.guess = f"gave up waiting {t.agent_wait_timeout_s:g} s for peers' data"
        return True
    fresh = node.h.beacons.get(k, {})
    # Peers alive by their tokens that may matter at k whose beacon for k is not in: wait, unless one is silent.
    missing = sorted(a for a in node.expected(k, clock) if a not in fresh)  # (not `- fresh.keys()`: many)
    if any(not silent(node.policy, node.h.heard.get(a, now), now) for a in missing) or (quiet and bool(missing)):
        return False
    if missing:
        node.guess = f"agents {missing} alive but silent for {node.policy.fresh_s:g} s"
    if node.linked[0] != k:
        node.link(k, np.array([st.px, st.py]))
    if node.k < 0 and k > 0:  # joining a mission under way: every peer's cached set (any revision) first
        return all(b.rev == 0 or node.sets.get(a) for a, b in fresh.items())
    need = {a: b.rev for a, b in fresh.items()} if node.brain.leader is not None else node.linked[1]
    # A set is there, or nothing to wait for: an empty set (rev 0), or a revision we merged already (a
    # peer that reconnected keeps counting; one restarted counts again from 1, and what it knew is
    # static knowledge we hold anyway).
    merged = node.merged_union if node.brain.leader is not None else node.merged
    return all(rev == 0 or rev in node.sets.get(a, ()) or rev <= merged.get(a, 0) for a, rev in need.items())

