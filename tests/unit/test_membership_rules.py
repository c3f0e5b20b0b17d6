"""Two rules of who speaks and who is there, at their exact thresholds: an agent's session pin moves to
another session only after the pinned one has been silent repin_after_s (measured from the last message,
not from the first); the monitor records a network split as soon as two agents (the fewest that make "several
agents lost together", docs/paper.md) are lost in one burst while others stay."""

from __future__ import annotations

from pathlib import Path

import pytest

from reconswarm.net.trust.admission import Admission, IntrusionKind, Pins
from reconswarm.net.wire import wire
from reconswarm.net.wire.keys import Keys
from reconswarm.paper.events import EventKind
from reconswarm.scenario.model import load
from tests.support import PAPER
from tests.unit.monitor_run import DT, IDS, started, token, tokens

S = load(PAPER)
KEYS = Keys("pins-0a1b2c")
REAL, OTHER = "agent2-zid", "someone-else"


def test_a_talking_agent_keeps_its_pin_however_long_ago_it_was_first_pinned() -> None:
    pins = Pins(repin_after_s=1.0)
    assert pins.agent(2, REAL, 0.0)  # pinned at 0 s
    for now in (0.4, 0.8, 1.2, 1.6, 2.0, 2.4, 2.8):  # the real agent keeps talking, every 0.4 s
        assert pins.agent(2, REAL, now)
        assert not pins.agent(2, OTHER, now + 0.2)  # another session 0.2 s after its last message: refused
    assert pins.agents[2] == (REAL, 2.8)  # last heard at 2.8 s, not first pinned at 0 s
    assert not pins.agent(2, OTHER, 3.79)  # silent 0.99 s: still the real one's
    assert pins.agent(2, OTHER, 3.8)  # silent repin_after_s: a restarted agent's new session takes over
    assert not pins.agent(2, REAL, 3.9)  # and the old one is now the stranger


def test_a_forged_command_long_after_the_first_pin_is_impersonation_while_the_agent_talks() -> None:
    adm = Admission(S)
    clock = wire.Clock(0, 0.0, tuple(a.id for a in S.agents))
    assert adm.check_clock(clock, "world-zid", KEYS.clock) is None
    key = KEYS.host(2, "cmd")
    for k in range(60):  # 3 s of wall time at 20 Hz: the real agent commands every tick
        now = 0.05 * k
        assert adm.check_cmd(wire.Cmd(2, 0, 1.0, 0.0), REAL, key, now=now, world_k=0) is None
        got = adm.check_cmd(wire.Cmd(2, 0, -5.0, 3.0), OTHER, key, now=now + 0.01, world_k=0)
        assert got is not None and got.kind is IntrusionKind.IMPERSONATION and got.source == OTHER, (k, got)
    # The same holds for the agent's beacons (the one pin per agent covers every message it sends).
    b = wire.Beacon(2, 0, 0.0, float(S.starts[S.agent_index(2), 0]), float(S.starts[S.agent_index(2), 1]),
                    float(S.radii[S.agent_index(2)]))
    got = adm.check_beacon(b, OTHER, KEYS.host_beacons((0, 0), 2), now=2.97)
    assert got is not None and got.kind is IntrusionKind.IMPERSONATION


# -------------------------------------------------------------------------------- the network split rule

@pytest.mark.parametrize("n_lost", [1, 2, 3])
def test_two_agents_lost_together_are_a_network_split_one_is_not(tmp_path: Path, n_lost: int) -> None:
    run = started(tmp_path)
    run.tick(0, 0.0)
    gone = IDS[3:3 + n_lost]
    for j, a in enumerate(gone):
        run.step(0.1 + 0.1 * j, token(a, False))
    run.tick(1, 0.95, quiet=tuple(gone))  # their tokens' ends confirmed: lost; the burst is open for 1 s
    assert [e.kind for e in run.events] == [EventKind.AGENT_LOST] * n_lost
    assert run.tick(2, 1.2, quiet=tuple(gone)) == []
    out = run.tick(3, 2.0, quiet=tuple(gone))
    if n_lost == 1:
        assert out == []  # a single loss stays agent_lost only
        return
    (split,) = out
    rest = sorted(set(IDS) - set(gone))
    assert split.kind == EventKind.SPLIT and split.cause == "network" and split.t == pytest.approx(DT)
    assert split.before == (tuple(IDS),) and set(split.after) == {tuple(rest), tuple(gone)}
    run.step(3.0, *tokens(True, gone))  # both back (their joins): the merge
    assert run.tick(4, 3.1) == []
    (merge,) = run.tick(5, 4.1)
    assert merge.kind == EventKind.MERGE and merge.cause == "network" and merge.after == (tuple(IDS),)
    assert set(merge.before) == {tuple(rest), tuple(gone)}
