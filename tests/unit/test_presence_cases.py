"""Who is there for the monitor (monitor/presence.py) in the cases its mutation run (bench/mutation.py) found
untested: a join's groups and Unix time, a split's groups ordered by their first agent, two changes judged
after one stall and a second stall, two splits and a merge of the first, a single loss after a merge, the
merge's time. Pure: tokens given to the membership, times given."""

from __future__ import annotations

from monitor.presence import Presence
from reconswarm.paper.events import Event, EventKind
from tests.unit.monitor_run import IDS, T

OFFSET = 1000.0


def present() -> Presence:
    """Everyone's token there at 0 s and the mission started (the first tokens are no joins)."""
    pr = Presence(IDS, T, OFFSET)
    for a in IDS:
        pr.members.token(a, True, 0.0, 0.0)
    assert pr.sync(0.0, 0.0, True, False, False) == []
    return pr


def tokens(pr: Presence, ids: list[int], up: bool, now: float) -> None:
    for a in ids:
        pr.members.token(a, up, now, 0.0)


def judge(pr: Presence, now: float, t: float = 0.0, held: bool = False) -> list[Event]:
    """What a monitor step at `now` records: changes (unless held), then the network's splits and merges."""
    return pr.sync(now, t, True, False, held) + ([] if held else pr.network(now))


def test_a_join_says_the_groups_before_and_after_and_its_unix_time() -> None:
    pr = present()
    tokens(pr, IDS[3:4], False, 0.1)
    assert [e.kind for e in judge(pr, 0.5)] == [EventKind.AGENT_LOST]
    tokens(pr, IDS[3:4], True, 0.6)
    (joined,) = judge(pr, 0.7123456, t=0.35)
    rest = tuple(a for a in IDS if a != IDS[3])
    assert (joined.kind, joined.agent, joined.t, joined.wall_unix) == (EventKind.AGENT_JOINED, IDS[3], 0.35,
                                                                       1000.712346)
    assert (joined.before, joined.after) == ((rest,), (tuple(IDS),))


def test_a_splits_groups_are_ordered_by_their_first_agent() -> None:
    """Agents 1 and 10 stay, 2..9 go: the groups after are (1, 10) then (2..9), by their first agent."""
    pr = present()
    gone = IDS[1:-1]
    tokens(pr, gone, False, 0.1)
    assert [e.kind for e in judge(pr, 0.5)] == [EventKind.AGENT_LOST] * len(gone)
    (split,) = judge(pr, 1.6)
    assert split.kind == EventKind.SPLIT and split.wall_unix == 1001.6
    assert split.after == ((IDS[0], IDS[-1]), tuple(gone))


def test_two_agents_lost_during_a_stall_are_both_judged_and_a_second_stall_is_held_again() -> None:
    pr = present()
    tokens(pr, IDS[:2], False, 0.1)
    assert judge(pr, 0.5, held=True) == []  # the world stalls: held
    assert [(e.kind, e.agent) for e in pr.judge(3.0, 0.0)] == [(EventKind.AGENT_LOST, a) for a in IDS[:2]]
    tokens(pr, IDS[2:3], False, 3.1)
    assert judge(pr, 3.5, held=True) == []  # a second stall: held again
    assert [(e.kind, e.agent) for e in pr.judge(6.0, 0.0)] == [(EventKind.AGENT_LOST, IDS[2])]


def test_two_splits_and_the_first_group_back_is_a_merge_then_a_single_loss_is_none() -> None:
    pr = present()
    tokens(pr, IDS[:2], False, 0.1)
    judge(pr, 0.5)
    assert [e.kind for e in judge(pr, 1.6)] == [EventKind.SPLIT]
    tokens(pr, IDS[2:4], False, 2.0)
    judge(pr, 2.5)
    assert [e.kind for e in judge(pr, 3.6)] == [EventKind.SPLIT]
    tokens(pr, IDS[:1], True, 4.0)  # the first group back, one agent after the other
    assert [e.kind for e in judge(pr, 4.1, t=2.0)] == [EventKind.AGENT_JOINED]
    tokens(pr, IDS[1:2], True, 4.5)
    assert [e.kind for e in judge(pr, 4.6, t=2.5)] == [EventKind.AGENT_JOINED]
    (merge,) = judge(pr, 5.2, t=3.0)
    assert merge.kind == EventKind.MERGE and merge.t == 2.0 and merge.wall_unix == 1005.2  # from the first back
    assert set(merge.before) == {tuple(IDS[:2]), tuple(IDS[4:])} and merge.after == ((*IDS[:2], *IDS[4:]),)
    # One of them lost alone and back: agent_lost and agent_joined only, no split and no merge.
    tokens(pr, IDS[:1], False, 6.0)
    assert [e.kind for e in judge(pr, 6.5)] == [EventKind.AGENT_LOST]
    tokens(pr, IDS[:1], True, 6.6)
    assert [e.kind for e in judge(pr, 6.7)] == [EventKind.AGENT_JOINED]
    assert judge(pr, 8.0) == []


def test_a_merge_orders_its_groups_by_their_first_agent_and_a_second_split_merges_again() -> None:
    """2..9 go and come back: the merge's groups before are (1, 10) then (2..9); then 2 and 3 go and come back:
    a second split and a second merge."""
    pr = present()
    gone = IDS[1:-1]
    tokens(pr, gone, False, 0.1)
    judge(pr, 0.5)
    assert [e.kind for e in judge(pr, 1.6)] == [EventKind.SPLIT]
    tokens(pr, gone, True, 2.0)
    judge(pr, 2.1)
    (merge,) = judge(pr, 3.2)
    assert merge.kind == EventKind.MERGE and merge.before == ((IDS[0], IDS[-1]), tuple(gone))
    again = IDS[1:3]
    tokens(pr, again, False, 4.0)
    judge(pr, 4.5)
    assert [e.kind for e in judge(pr, 5.6)] == [EventKind.SPLIT]
    tokens(pr, again, True, 6.0)
    judge(pr, 6.1)
    (merge,) = judge(pr, 7.2)
    assert merge.kind == EventKind.MERGE and merge.after == (tuple(IDS),)


def test_a_partitioned_agent_back_and_lost_again_within_the_burst_is_no_merge() -> None:
    """1 and 2 split off; 1 comes back and goes again before the burst ends: nobody is back at its end, so no
    merge (only its join and its loss); both back later are the merge."""
    pr = present()
    tokens(pr, IDS[:2], False, 0.1)
    judge(pr, 0.5)
    assert [e.kind for e in judge(pr, 1.6)] == [EventKind.SPLIT]
    tokens(pr, IDS[:1], True, 2.0)
    assert [(e.kind, e.agent) for e in judge(pr, 2.1)] == [(EventKind.AGENT_JOINED, IDS[0])]
    tokens(pr, IDS[:1], False, 2.2)
    assert [(e.kind, e.agent) for e in judge(pr, 2.6)] == [(EventKind.AGENT_LOST, IDS[0])]
    assert judge(pr, 3.2) == [] and pr.alive_ids() == IDS[2:]
    tokens(pr, IDS[:2], True, 4.0)
    assert [e.kind for e in judge(pr, 4.1)] == [EventKind.AGENT_JOINED] * 2
    (merge,) = judge(pr, 5.2)
    assert merge.kind == EventKind.MERGE and merge.before == (tuple(IDS[:2]), tuple(IDS[2:]))


def ended(pr: Presence, now: float, t: float = 0.0) -> list[Event]:
    """A monitor step while an end is claimed: no change is judged (agents leave when the mission ends)."""
    return pr.sync(now, t, True, True, False)


def test_an_agent_gone_while_an_end_is_claimed_and_back_once_it_is_refused_is_alive_and_in_no_burst() -> None:
    """Agent 1's token goes while an end is claimed (not judged); the end is refused and agent 1 is back: it is
    alive as recorded, no event, and it is in no burst: 2 and 3 lost later are a split from their own loss."""
    pr = present()
    tokens(pr, IDS[:1], False, 0.1)
    assert ended(pr, 0.5) == []
    tokens(pr, IDS[:1], True, 0.6)  # the end refused: judged again
    assert judge(pr, 0.7, t=0.3) == [] and pr.alive_ids() == IDS
    tokens(pr, IDS[1:3], False, 1.0)
    assert [e.kind for e in judge(pr, 1.4, t=0.6)] == [EventKind.AGENT_LOST] * 2
    assert judge(pr, 1.8, t=0.8) == []  # 0.4 s after the losses: the burst goes on
    (split,) = judge(pr, 2.5, t=1.0)
    assert split.kind == EventKind.SPLIT and split.t == 0.6 and split.after == ((IDS[0], *IDS[3:]), tuple(IDS[1:3]))


def test_an_agent_gone_while_an_end_is_claimed_is_lost_once_the_end_is_refused() -> None:
    """The mission did not end (the end was refused): an agent gone meanwhile and still gone is lost."""
    pr = present()
    tokens(pr, IDS[:1], False, 0.1)
    assert ended(pr, 0.5) == []
    lost = judge(pr, 0.7, t=0.3)  # the end refused: judged again
    assert [(e.kind, e.agent) for e in lost] == [(EventKind.AGENT_LOST, IDS[0])]
    assert pr.alive_ids() == IDS[1:]
