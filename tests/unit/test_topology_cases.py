"""The swarm graph's less travelled paths (reconswarm/paper/topology.py), each against the rule it must keep
(docs/paper.md): an edge forms at <= link range and, once made, holds up to link range + the hysteresis;
groups are the connected components over active agents; a change of grouping held 1 s is a split (a group
dividing) or a merge (groups joining), reported once, timed at the change and confirmed at the tick it
held 1 s. Covers the tracker's shortcuts (the same edges, removed edges certified not to split a group,
caller-given candidate pairs in any order) against the plain definition, and diff's many-to-many cases."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pytest

from reconswarm.geometry.plane import norm2
from reconswarm.paper.topology import MAX_CERTIFIED, TopologyTracker, diff, graph_edges, labels

LINK = 40.0
DT = 0.05
NONE = np.zeros((0, 2), dtype=np.int64)


def f(*groups: set[int]) -> tuple[frozenset[int], ...]:
    return tuple(frozenset(g) for g in groups)


def feed(tr: TopologyTracker, seq: list[np.ndarray], t0: float = 0.0, active: np.ndarray | None = None,
         cand_of=None) -> list[tuple[float, dict]]:
    out = []
    for k, p in enumerate(seq):
        t = round(t0 + k * DT, 9)
        act = np.ones(p.shape[0], dtype=bool) if active is None else active
        if cand_of is None:
            evs = tr.step(t, p, act)
        else:
            cand = cand_of(p)
            evs = tr.step(t, p, act, cand, norm2(p[cand[:, 0]] - p[cand[:, 1]]))
        out += [(t, e) for e in evs]
    return out


def hold(p: Sequence[Sequence[float]], seconds: float) -> list[np.ndarray]:
    return [np.asarray(p, dtype=np.float64)] * round(seconds / DT)


# ------------------------------------------------------------------------------------------ labels


def test_labels_of_no_agent_and_of_one_agent() -> None:
    lab = labels(0, NONE, np.zeros(0, dtype=bool))
    assert lab.shape == (0,) and lab.dtype == np.int64
    assert labels(1, NONE, np.array([True])).tolist() == [0]  # one agent: a group of its own
    assert labels(1, NONE, np.array([False])).tolist() == [-1]
    tr = TopologyTracker(np.array([7], dtype=np.int64), LINK)
    tr.step(0.0, np.zeros((1, 2)), np.array([True]))
    assert tr.current == f({7}) and tr.n_groups == 1


# ------------------------------------------------------------------------------------------ graph_edges


def test_hysteresis_band_found_from_the_previous_edges_alone() -> None:
    """Without prev_keys, graph_edges finds whether a pair in the band was linked from prev (i * N + j)."""
    p = np.array([[0.0, 0.0], [100.0, 0.0], [141.0, 0.0]])  # 1-2 at 41 m: in the band (40, 42]
    act = np.ones(3, dtype=bool)
    assert graph_edges(p, act, np.array([[1, 2]], dtype=np.int64), LINK).tolist() == [[1, 2]]
    assert graph_edges(p, act, np.array([[0, 1]], dtype=np.int64), LINK).shape == (0, 2)  # 1-2 not linked before
    assert graph_edges(p, act, NONE, LINK).shape == (0, 2)


def test_a_wider_hysteresis_holds_an_edge_to_link_plus_its_width() -> None:
    tr = TopologyTracker(np.array([1, 2], dtype=np.int64), LINK, hysteresis_m=5.0)
    events = feed(tr, hold([[0, 0], [40, 0]], 1.0) + hold([[0, 0], [44.5, 0]], 2.0))
    assert events == [] and tr.n_groups == 1  # 44.5 m <= 40 + 5: still linked
    events = feed(tr, hold([[0, 0], [45.5, 0]], 1.5), t0=3.0)
    assert [e["kind"] for _, e in events] == ["split"]


# ------------------------------------------------------------------------------------------ the tracker


def test_event_times_are_the_tick_times() -> None:
    together, apart = [[0, 0], [30, 0]], [[0, 0], [90, 0]]
    tr = TopologyTracker(np.array([1, 2], dtype=np.int64), LINK)
    events = feed(tr, hold(together, 1.55) + hold(apart, 1.5))
    ((t, ev),) = events
    assert ev["t"] == pytest.approx(1.55, abs=1e-12)  # the change
    assert ev["t_confirmed"] == pytest.approx(2.55, abs=1e-12) and t == pytest.approx(2.55, abs=1e-12)


def test_an_agent_going_inactive_leaves_the_groups_even_when_no_edge_changes() -> None:
    ids = np.array([1, 2, 3], dtype=np.int64)
    p = np.array([[0.0, 0.0], [30.0, 0.0], [500.0, 0.0]])  # agent 3 alone, far away: no edge of its own
    tr = TopologyTracker(ids, LINK)
    tr.step(0.0, p, np.ones(3, dtype=bool))
    assert tr.current == f({1, 2}, {3})
    tr.step(0.05, p, np.array([True, True, False]))  # the same edges, agent 3 gone
    assert tr.current == f({1, 2}) and tr.n_groups == 1
    tr.step(0.1, p, np.ones(3, dtype=bool))  # back
    assert tr.current == f({1, 2}, {3})


def test_removed_edges_split_a_group_when_any_one_of_them_was_a_bridge() -> None:
    """Two edges go at one tick: 0-1 (0 and 1 still share neighbour 2) and the bridge 2-3. The group divides
    ({1, 2, 3} | {4}): one removed edge with a shared neighbour does not vouch for the other."""
    before = [[0, 0], [30, 0], [15, 20], [15, 50]]  # a triangle 0-1-2, and 3 hanging on 2 (30 m)
    after = [[-20, 0], [50, 0], [15, 20], [15, 100]]  # 0-1 70 m; 0-2, 1-2 40.3 m (band: kept); 2-3 80 m
    tr = TopologyTracker(np.array([1, 2, 3, 4], dtype=np.int64), LINK)
    feed(tr, hold(before, 1.0))
    assert tr.edges.tolist() == [[0, 1], [0, 2], [1, 2], [2, 3]]
    events = feed(tr, hold(after, 1.5), t0=1.0)
    assert tr.edges.tolist() == [[0, 2], [1, 2]]
    assert [(e["kind"], e["before"], e["after"]) for _, e in events] == [("split", [[1, 2, 3, 4]], [[1, 2, 3], [4]])]


def test_a_split_removing_more_edges_than_are_certified_one_by_one() -> None:
    """Two clusters of 5 agents, every cross pair linked (25 edges > MAX_CERTIFIED), pull apart at once."""
    a = [[0.0, 3.0 * k] for k in range(5)]
    near = [[20.0, 3.0 * k] for k in range(5)]
    far = [[200.0, 3.0 * k] for k in range(5)]
    tr = TopologyTracker(np.arange(1, 11, dtype=np.int64), LINK)
    feed(tr, hold(a + near, 1.0))
    cross = [e for e in tr.edges.tolist() if e[0] < 5 <= e[1]]
    assert len(cross) == 25 > MAX_CERTIFIED
    events = feed(tr, hold(a + far, 1.5), t0=1.0)
    assert [(e["kind"], e["after"]) for _, e in events] == [("split", [[1, 2, 3, 4, 5], [6, 7, 8, 9, 10]])]
    assert tr.n_groups == 2


def test_candidate_pairs_given_in_any_order_give_the_same_graph_and_events() -> None:
    """A line of 4 agents 30 m apart stretched into the band (41 m apart: every edge held by hysteresis),
    then pulled apart: the caller's candidate pairs (with their distances), in an order that is not sorted,
    give what the tracker finds alone."""
    seq = (hold([[0, 0], [30, 0], [60, 0], [90, 0]], 1.0) + hold([[0, 0], [41, 0], [82, 0], [123, 0]], 2.0)
           + hold([[0, 0], [41, 0], [150, 0], [191, 0]], 1.5))

    def unsorted_cand(p: np.ndarray) -> np.ndarray:
        order = [(0, 1), (2, 3), (1, 2), (0, 2), (1, 3), (0, 3)]  # a superset of the pairs within 42 m
        return np.array(order, dtype=np.int64)

    alone = TopologyTracker(np.array([1, 2, 3, 4], dtype=np.int64), LINK)
    given = TopologyTracker(np.array([1, 2, 3, 4], dtype=np.int64), LINK)
    ev_alone = feed(alone, seq)
    ev_given = feed(given, seq, cand_of=unsorted_cand)
    assert [(e["kind"], e["before"], e["after"]) for _, e in ev_alone] == [("split", [[1, 2, 3, 4]], [[1, 2], [3, 4]])]
    assert ev_given == ev_alone
    assert sorted(map(tuple, given.edges.tolist())) == sorted(map(tuple, alone.edges.tolist())) == [(0, 1), (2, 3)]


# ------------------------------------------------------------------------------------------ diff


def test_diff_reports_every_component_after_a_merge_of_the_first_groups() -> None:
    """{1} {2} merge while {3, 4} splits: both reported."""
    got = diff(f({1}, {2}, {3, 4}), f({1, 2}, {3}, {4}))
    assert sorted(got) == sorted([("merge", [[1], [2]], [[1, 2]]), ("split", [[3, 4]], [[3], [4]])])


def test_diff_reports_a_merge_once() -> None:
    """{1} and {3} join, {2} stays: one merge, not one per group it touched."""
    assert diff(f({1}, {2}, {3}), f({1, 3}, {2})) == [("merge", [[1], [3]], [[1, 3]])]


def test_diff_many_to_many_with_pairs_that_do_not_meet() -> None:
    """{1, 2} {3, 4} -> {1} {2, 3} {4}: both groups split, {2} and {3} merge; {1, 2} and {4} never meet."""
    got = diff(f({1, 2}, {3, 4}), f({1}, {2, 3}, {4}))
    assert sorted(got) == sorted([("split", [[1, 2]], [[1], [2]]), ("split", [[3, 4]], [[3], [4]]),
                                  ("merge", [[2], [3]], [[2, 3]])])


def test_diff_many_to_many_where_a_group_moves_whole() -> None:
    """{1, 2} {3, 4} -> {1, 2, 3} {4}: only {3, 4} splits and {1, 2} + {3} merge; {1, 2} moves whole (no split
    of it) and {4} stays whole (no merge into it)."""
    got = diff(f({1, 2}, {3, 4}), f({1, 2, 3}, {4}))
    assert sorted(got) == sorted([("split", [[3, 4]], [[3], [4]]), ("merge", [[1, 2], [3]], [[1, 2, 3]])])
