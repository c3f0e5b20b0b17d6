"""Where a lockstep run leaves the in-process engine's (issue 22, case 8): the first tick the world steps with
a robot lacking that tick's command (an agent frozen or lost: its robot held, then stopped), which comes
before any agent acts on a guess. The world says it in its end statistics; the monitor's
`determinism_lost_at_s` is the earliest of it and the agents' guesses."""

from __future__ import annotations

from simworld.world import WorldNode
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
