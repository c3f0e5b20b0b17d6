"""Where a lockstep run leaves the in-process engine's (issue 22, case 8): the first tick the world steps with
a robot lacking that tick's command (an agent frozen or lost: its robot held, then stopped), which comes
before any agent acts on a guess. The world says it in its end statistics; the monitor's
`determinism_lost_at_s` is the earliest of it and the agents' guesses."""

from __future__ import annotations

from pathlib import Path

import pytest

from reconswarm.net import wire
from reconswarm.record.store import RunRecord
from reconswarm.record.summary import summarize
from simworld.world import WorldNode
from tests.unit.test_monitor_node import DT, node_for, tick
from tests.unit.test_world_node import IDS, S, T, advance, command_all, started


def _run_ticks(node: WorldNode, ticks: range, now: float, skip: tuple[int, ...] = ()) -> float:
    for k in ticks:
        node.step(now)  # publish tick k
        command_all(node, k, (1.0, 0.0), now, skip=skip)
        if skip:
            advance(node, now, now + T.step_timeout_s)  # the step times out: the silent robot is held
            now += T.step_timeout_s
        else:
            node.step(now)
        assert node.k == k + 1
    return now


def test_every_tick_commanded_is_the_engines() -> None:
    node = started()
    _run_ticks(node, range(0, 5), 0.0)
    assert node.uncommanded_k == -1 and "uncommanded_from_s" not in node.stats()


def test_the_first_tick_stepped_without_a_robots_command_is_said() -> None:
    node = started()
    now = _run_ticks(node, range(0, 3), 0.0)
    now = _run_ticks(node, range(3, 5), now, skip=(IDS[4],))  # agent frozen from tick 3
    node.agent_up(IDS[4], False)  # then lost: not waited for, its robot stands still, uncommanded
    for k in range(5, 7):
        node.step(now)
        command_all(node, k, (1.0, 0.0), now, skip=(IDS[4],))
        node.step(now)
        assert node.k == k + 1
    assert node.uncommanded_k == 3
    assert node.stats()["uncommanded_from_s"] == round(3 * S.meta.dt_s, 9)


@pytest.mark.parametrize(("guessed_k", "uncommanded_k", "lost_k"), [(-1, -1, None), (8, -1, 8), (-1, 3, 3), (8, 3, 3),
                                                                    (2, 3, 2)])
def test_determinism_lost_at_is_the_earliest_of_the_agents_guess_and_the_worlds_uncommanded_tick(
        tmp_path: Path, guessed_k: int, uncommanded_k: int, lost_k: int | None) -> None:
    node = node_for(tmp_path)
    for k in range(10):
        tick(node, k, 0.01 * k)
        if 0 <= guessed_k <= k:
            node.telemetry(IDS[0], 0, guessed_k)
    stats = {} if uncommanded_k < 0 else {"uncommanded_from_s": round(uncommanded_k * DT, 9)}
    node.clock(wire.Clock(10, 10 * DT, tuple(IDS), wire.ClockMode.LOCKSTEP, 0.0, True, "duration", 0, stats), 0.11)
    node.finish(0.2, 0)
    with RunRecord(tmp_path / "run.db") as rec:
        s = summarize(rec)
    assert (s["deterministic"], s["determinism_lost_at_s"]) == ((True, None) if lost_k is None
                                                                else (False, round(lost_k * DT, 9)))
    assert "uncommanded_from_s" not in s  # one name for it: determinism_lost_at_s
