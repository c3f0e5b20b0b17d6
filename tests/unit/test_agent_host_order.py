"""An agent host hands its nodes what zenoh brought in the order it came (agent/host.py, its inbox:
reconswarm/net/runtime/inbox.py `ordered`).

Lockstep's wait set for tick k is built from the peers' beacons of tick k-1 that are in when the agent's state of
k comes (agent/neighbours.py). Each of those beacons is put before its agent's command of k-1, which the world
waits for before it publishes any state of k: through the one link a client has to its router, the beacon comes
first. The host must not undo that order: a subscription whose samples were handed over on a thread of its own
(zenoh-python's default) let a swamped cell subscription hand a beacon of k-1 over after the state of k (issue 52:
the peer was left out of the wait set, its beacon of k within reach was "not expected", lockstep lost
determinism). Here, with real zenoh on 127.0.0.1: a burst of beacons on a cell key, then a state, must reach the
inbox beacons first, every time."""

from __future__ import annotations

import time
from typing import Any

from agent.node import AgentNode
from reconswarm.net.wire.batch import batch_to_wire
from reconswarm.net.wire.hostwire import state_batches
from tests.support import wait_subscribed
from tests.unit.test_agent_host_cases import make_host, state
from tests.unit.test_agent_host_routing import KEYS, S, at_start
from tests.unit.test_agent_host_sessions import take_own_tokens, two_sessions

BURST = 3000  # beacons put on one cell key before the state (a flood on the cell subscriptions)
ROUNDS = 10


def test_a_burst_of_beacons_on_a_cell_reaches_the_inbox_before_the_state_put_after_it() -> None:
    with two_sessions() as (z, out):
        h = make_host(z, (1,))
        try:
            home3 = AgentNode(S, 3, 0.0).nb.home
            for key in (KEYS.host(1, "state"), KEYS.host_beacons(home3, 3)):  # (the host's declarations reach `out`)
                wait_subscribed(out, key)
            take_own_tokens(h.inbox, (1,))
            burst, marker = batch_to_wire(3, [at_start(3)]), batch_to_wire(3, [at_start(3, 1)])
            for rounds in range(ROUNDS):
                for _ in range(BURST):
                    out.put(KEYS.host_beacons(home3, 3), burst)
                out.put(KEYS.host(1, "state"), state_batches(1, [state(1, rounds)])[0][0])
                out.put(KEYS.host_beacons(home3, 3), marker)  # (once in, every one of the burst is: one subscription)
                got: list[Any] = []
                deadline = time.monotonic() + 60.0
                while not any(it[1] == marker for _tag, it in got) and time.monotonic() < deadline:
                    got += h.inbox.take(None, 0.5, 1)  # (as the loop does: the state wakes it)
                payloads = [it[1] for _tag, it in got]
                assert marker in payloads, (rounds, len(payloads))
                at = payloads.index(state_batches(1, [state(1, rounds)])[0][0])
                late = sum(1 for p in payloads[at:] if p == burst)
                assert late == 0, f"round {rounds}: {late} beacons put before the state came after it"
        finally:
            h.close()
