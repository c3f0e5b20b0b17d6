"""A lone agent's node with its host's one job for it done at once: the law of its plan (agent/host.py `answers`,
which computes it for every hosted agent's plan of a round; here the round holds one)."""

from __future__ import annotations

from collections.abc import Iterable

from agent.brain import Plan, commands
from agent.messages import Input, Law, Output
from agent.node import AgentNode


class SoloNode(AgentNode):
    """`step` returns the command its plan leads to (and whatever follows it), as the runtime's answers round does."""

    def step(self, batch: Iterable[Input], now_s: float) -> list[Output]:
        out = super().step(batch, now_s)
        while out and isinstance(plan := out[-1], Plan):
            out.pop()
            out += super().step([Law(plan.k, *commands([plan])[0])], now_s)
        return out
