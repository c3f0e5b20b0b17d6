"""Where a lockstep run leaves the in-process engine's (issue 22, case 8): the first tick the world steps with
a robot lacking that tick's command (an agent frozen or lost: its robot held, then stopped), which comes
before any agent acts on a guess. The world says it in its end statistics; the monitor's
`determinism_lost_at_s` is the earliest of it and the agents' guesses."""

from __future__ import annotations

from pathlib import Path

import pytest

from reconswarm.record.summary import summarize
from tests.unit.monitor_run import DT, clock, report
from tests.unit.monitor_run import started as monitor_started
from tests.unit.test_world_node import IDS, S, advance, commands, run_ticks, started, tokens


def test_every_tick_commanded_is_the_engines() -> None:
    node = started()
    run_ticks(node, range(0, 5), 0.0)
    assert node.uncommanded_k == -1 and "uncommanded_from_s" not in node.stats()


def test_the_first_tick_stepped_without_a_robots_command_is_said() -> None:
    node = started()
    now = run_ticks(node, range(0, 3), 0.0)
    now = run_ticks(node, range(3, 5), now, skip=(IDS[4],))  # agent frozen from tick 3
    advance(node, now, now + 0.5, every_s=0.1, inputs=tokens(IDS[4:5], up=False))  # then lost (confirmed)
    now += 0.5
    assert IDS[4] not in node.alive
    for k in range(5, 7):  # not waited for; its robot stands still, uncommanded
        node.step([], now)
        node.step(commands(k, (1.0, 0.0), now, skip=(IDS[4],)), now)
        assert node.k == k + 1
    assert node.uncommanded_k == 3
    assert node.stats()["uncommanded_from_s"] == round(3 * S.meta.dt_s, 9)


@pytest.mark.parametrize(("guessed_k", "uncommanded_k", "lost_k"), [(-1, -1, None), (8, -1, 8), (-1, 3, 3), (8, 3, 3),
                                                                    (2, 3, 2)])
def test_determinism_lost_at_is_the_earliest_of_the_agents_guess_and_the_worlds_uncommanded_tick(
        tmp_path: Path, guessed_k: int, uncommanded_k: int, lost_k: int | None) -> None:
    run = monitor_started(tmp_path)
    for k in range(10):
        run.tick(k, 0.01 * k)
        if 0 <= guessed_k <= k:
            run.step(0.01 * k, report(IDS[0], 0, guessed_k))
    stats = {} if uncommanded_k < 0 else {"uncommanded_from_s": round(uncommanded_k * DT, 9)}
    run.step(0.11, clock(10, end=True, reason="duration", stats=stats))
    run.stop(0.2)
    with run.record() as rec:
        s = summarize(rec)
    assert (s["deterministic"], s["determinism_lost_at_s"]) == ((True, None) if lost_k is None
                                                                else (False, round(lost_k * DT, 9)))
    assert "uncommanded_from_s" not in s  # one name for it: determinism_lost_at_s
