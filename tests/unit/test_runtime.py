"""The one runtime (net/runtime/runtime.py) against its rules, with nodes and an inbox of our own (no zenoh: the
runtime's only zenoh call, the uplink's, finds no router on a session object without one and follows nothing).

Rules: one wake-up per batch, waiting for the fewest messages any node still needs (less what the port holds for
it; at once if that is all it needs), for the urgent samples of the nodes that need one, or for the nearest node
timer; a node is stepped when it has inputs, when its timer is due, or every
poll_s; a signal reaches every node once as Stop; a node's Exit takes it out of the loop and the others go on; a
port's act can stop the whole loop."""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

from reconswarm.net.node import Exit, Stop
from reconswarm.net.runtime.runtime import Runtime


class NoRouters:
    """A session object without routers (a peer's): the uplink follows nothing."""

    class info:  # (zenoh's attribute name)
        @staticmethod
        def routers_zid() -> list[str]:
            return []


class Stopper:
    def __init__(self) -> None:
        self.stopped = False


class Inbox:
    """Hands out scripted batches, one per take; records what each take asked for."""

    def __init__(self, batches: list[list[Any]], on_take: Any = None) -> None:
        self.batches, self.on_take = batches, on_take
        self.asked: list[tuple[int | None, float | None]] = []
        self.urgent: list[int] = []

    def take(self, want: int | None, timeout: float | None, urgent: int = 1) -> Sequence[Any]:
        self.asked.append((want, timeout))
        self.urgent.append(urgent)
        if self.on_take is not None:
            self.on_take(len(self.asked))
        return self.batches.pop(0) if self.batches else []


class Node:
    """Steps recorded; exits when it is given ("exit", code) or Stop; returns ("say", x) for ("echo", x)."""

    def __init__(self, need: int | None = None, wake: float | None = None) -> None:
        self.steps: list[list[Any]] = []
        self.need, self.wake = need, wake

    def step(self, inputs: Sequence[Any], now_s: float) -> list[Any]:
        self.steps.append(list(inputs))
        out: list[Any] = []
        for m in inputs:
            if isinstance(m, Stop):
                out.append(Exit(0, "stopped"))
            elif m[0] == "exit":
                out.append(Exit(m[1]))
            elif m[0] == "echo":
                out.append(("say", m[1]))
        return out

    def wake_at_s(self) -> float | None:
        return self.wake

    def awaiting(self, now_s: float) -> int | None:
        return self.need


class Adapter:
    """Routes ("to", who, message) items to node `who`; records what it was asked to do."""

    def __init__(self, stop_on: Any = None) -> None:
        self.acted: list[tuple[Any, Any]] = []
        self.idled: list[Any] = []
        self.gone: list[tuple[Any, int]] = []
        self.stop_on = stop_on
        self.local: dict[Any, int] = {}

    def route(self, items: Sequence[Any], now_s: float) -> dict[Any, list[Any]]:
        out: dict[Any, list[Any]] = {}
        for _to, who, m in items:
            out.setdefault(who, []).append(m)
        return out

    def act(self, who: Any, out: Any, now_s: float) -> bool:
        self.acted.append((who, out))
        return out == self.stop_on

    def idle(self, who: Any, now_s: float) -> None:
        self.idled.append(who)

    def exited(self, who: Any, code: Exit, now_s: float) -> None:
        self.gone.append((who, code.code))

    def pending(self) -> dict[Any, int]:
        return self.local

    def answers(self, now_s: float) -> dict[Any, list[Any]]:
        return {}


class AskingAdapter(Adapter):
    """Answers ("ask", x) outputs after the round, all at once: ("answer", x, how many were asked together)."""

    def __init__(self) -> None:
        super().__init__()
        self.asked: list[tuple[Any, Any]] = []

    def act(self, who: Any, out: Any, now_s: float) -> bool:
        if out[0] == "ask":
            self.asked.append((who, out[1]))
            return False
        return super().act(who, out, now_s)

    def answers(self, now_s: float) -> dict[Any, list[Any]]:
        asked, self.asked = self.asked, []
        return {who: [("answer", x, len(asked))] for who, x in asked}


class AskingNode(Node):
    """("job", x) -> asks ("ask", x); ("answer", x, n) -> ("say", (x, n)), or asks again once for x < 0."""

    def step(self, inputs: Sequence[Any], now_s: float) -> list[Any]:
        out = super().step(inputs, now_s)
        for m in inputs:
            if not isinstance(m, Stop) and m[0] == "job":
                out.append(("ask", m[1]))
            elif not isinstance(m, Stop) and m[0] == "answer":
                out.append(("ask", -m[1]) if m[1] < 0 else ("say", (m[1], m[2])))
        return out


def runtime(inbox: Inbox, stop: Stopper | None = None, poll_s: float = 1000.0) -> Runtime:
    return Runtime(NoRouters(), "test", stop or Stopper(), inbox, poll_s)  # type: ignore[arg-type]


def test_each_node_gets_its_own_inputs_and_its_outputs_are_acted_in_order() -> None:
    a, b = Node(), Node()
    inbox = Inbox([[("to", 1, ("echo", "x")), ("to", 2, ("echo", "y")), ("to", 1, ("echo", "z"))],
                   [("to", 1, ("exit", 0)), ("to", 2, ("exit", 4))]])
    port = Adapter()
    exits = runtime(inbox).run({1: a, 2: b}, port, cohosting=port)
    assert a.steps[0] == [("echo", "x"), ("echo", "z")] and b.steps[0] == [("echo", "y")]
    assert port.acted == [(1, ("say", "x")), (1, ("say", "z")), (2, ("say", "y"))]
    assert {w: e.code for w, e in exits.items()} == {1: 0, 2: 4} and port.gone == [(1, 0), (2, 4)]
    assert port.idled == [1, 2]  # after a step that did not exit


def test_a_node_with_nothing_new_and_no_timer_due_is_not_stepped() -> None:
    a, b = Node(), Node()
    inbox = Inbox([[("to", 1, ("echo", 1))], [("to", 1, ("echo", 2))],
                   [("to", 1, ("exit", 0)), ("to", 2, ("exit", 0))]])
    runtime(inbox).run({1: a, 2: b}, Adapter())
    assert len(a.steps) == 3
    assert b.steps == [[], [("exit", 0)]]  # once at first (its poll), then only when it had input


def test_a_due_timer_steps_the_node_without_input() -> None:
    a = Node(wake=time.monotonic() - 1.0)  # overdue
    inbox = Inbox([[], [], [("to", 1, ("exit", 0))]])
    runtime(inbox).run({1: a}, Adapter())
    assert a.steps == [[], [], [("exit", 0)]]
    assert all(timeout == 0.0 for _want, timeout in inbox.asked)  # (an overdue timer: no waiting)


def test_the_wait_is_for_the_fewest_messages_any_node_needs() -> None:
    a, b, c = Node(need=5), Node(need=2), Node(need=None)
    inbox = Inbox([[("to", w, ("exit", 0)) for w in (1, 2, 3)]])
    runtime(inbox, poll_s=0.3).run({1: a, 2: b, 3: c}, Adapter())
    assert inbox.asked == [(2, 0.3)]
    assert inbox.urgent == [1]  # (node 3 needs an urgent sample of its own: its state)


def test_the_wait_is_for_the_urgent_samples_of_every_node_that_needs_one() -> None:
    nodes = {w: Node(need=None) for w in (1, 2, 3)} | {4: Node(need=2)}
    inbox = Inbox([[("to", w, ("exit", 0)) for w in (1, 2, 3, 4)]])
    runtime(inbox, poll_s=0.3).run(nodes, Adapter())
    assert inbox.asked == [(2, 0.3)] and inbox.urgent == [3]


def test_what_the_port_holds_for_a_node_counts_toward_what_it_needs() -> None:
    port = Adapter()
    port.local = {1: 2, 2: 1}  # (held for node 1: 2 of the 5 it needs; for node 2: 1 of its 4)
    inbox = Inbox([[("to", w, ("exit", 0)) for w in (1, 2)]])
    runtime(inbox, poll_s=0.3).run({1: Node(need=5), 2: Node(need=4)}, port, cohosting=port)
    assert inbox.asked == [(3, 0.3)]


def test_no_waiting_when_what_the_port_holds_is_all_a_node_needs() -> None:
    port = Adapter()
    port.local = {2: 3}
    inbox = Inbox([[("to", w, ("exit", 0)) for w in (1, 2)]])
    runtime(inbox, poll_s=0.3).run({1: Node(need=5), 2: Node(need=3)}, port, cohosting=port)
    assert inbox.asked == [(1, 0.0)]  # (node 2 steps now: nothing need arrive)


def test_what_the_port_holds_for_a_node_that_needs_its_own_state_first_is_no_reason_to_wake() -> None:
    port = Adapter()
    port.local = {1: 4}
    inbox = Inbox([[("to", 1, ("exit", 0))]])
    runtime(inbox, poll_s=0.3).run({1: Node(need=None)}, port, cohosting=port)
    assert inbox.asked == [(None, 0.3)]


def test_a_signal_reaches_every_node_once_as_stop() -> None:
    stop = Stopper()
    a, b = Node(), Node()

    def signal_at(n: int) -> None:
        stop.stopped = n >= 2

    inbox = Inbox([[("to", 1, ("echo", 1))], []], on_take=signal_at)
    port = Adapter()
    exits = runtime(inbox, stop).run({1: a, 2: b}, port, cohosting=port)
    assert [sum(isinstance(m, Stop) for m in s) for s in a.steps] == [0, 1]
    assert [sum(isinstance(m, Stop) for m in s) for s in b.steps] == [0, 1]
    assert {w: (e.code, e.reason) for w, e in exits.items()} == {1: (0, "stopped"), 2: (0, "stopped")}


def test_a_port_can_stop_the_whole_loop() -> None:
    a, b = Node(), Node()
    inbox = Inbox([[("to", 1, ("echo", "new session")), ("to", 2, ("echo", "later"))]])
    port = Adapter(stop_on=("say", "new session"))
    rt = runtime(inbox)
    exits = rt.run({1: a, 2: b}, port, cohosting=port)
    assert rt.interrupted and exits == {}
    assert port.acted == [(1, ("say", "new session"))] and b.steps == []  # nothing after the request


def test_what_nodes_ask_in_a_round_is_answered_together_before_the_next_take() -> None:
    """An agent host's law: every node's plan of a round is answered at once, and the nodes are stepped with
    the answers before the inbox is read again; an answer that leads to another question is answered too."""
    a, b, c = AskingNode(), AskingNode(), AskingNode()
    takes: list[int] = []
    port = AskingAdapter()
    inbox = Inbox([[("to", 1, ("job", 5)), ("to", 2, ("job", -6))],
                   [("to", 1, ("exit", 0)), ("to", 2, ("exit", 0)), ("to", 3, ("exit", 0))]],
                  on_take=lambda n: takes.append(len(port.acted)))
    runtime(inbox).run({1: a, 2: b, 3: c}, port, cohosting=port)
    assert a.steps[1] == [("answer", 5, 2)] and b.steps[1] == [("answer", -6, 2)]  # (asked together: 2)
    assert b.steps[2] == [("answer", 6, 1)]  # its second question, answered alone
    assert port.acted == [(1, ("say", (5, 2))), (2, ("say", (6, 1)))]
    assert takes == [0, 2]  # both answered and acted before the second take
    assert c.steps == [[], [("exit", 0)]]  # (asked nothing: not stepped with the answers)
