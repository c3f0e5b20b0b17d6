"""The swarm graph, its split / merge events (reconswarm/paper/topology.py) and the safety metrics
(reconswarm/record/safety.py) on constructed cases."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from reconswarm.paper.topology import TopologyTracker, _changes, diff, graph_edges, groups_of, labels
from reconswarm.record.safety import SafetyMonitor, nearest_gap

DT = 0.05
LINK = 40.0


def run_tracker(positions, ids=None, active=None, dt: float = DT, t0: float = 0.0):
    """Feed a sequence of (N, 2) positions; return [(t, event), ...] and the tracker."""
    positions = [np.asarray(p, dtype=np.float64) for p in positions]
    n = positions[0].shape[0]
    tr = TopologyTracker(np.asarray(ids if ids is not None else np.arange(1, n + 1), dtype=np.int64), LINK)
    out = []
    for k, p in enumerate(positions):
        t = t0 + k * dt
        act = np.ones(n, dtype=bool) if active is None else np.asarray(active[k], dtype=bool)
        for ev in tr.step(round(t, 9), p, act):
            out.append((round(t, 9), ev))
    return out, tr


def line(xs) -> np.ndarray:
    return np.array([[x, 0.0] for x in xs])


def hold(p, seconds: float) -> list[np.ndarray]:
    return [np.asarray(p, dtype=np.float64)] * round(seconds / DT)


# ------------------------------------------------------------------------------------------ graph


def test_graph_edges_hysteresis():
    active = np.ones(2, dtype=bool)
    none = np.zeros((0, 2), dtype=np.int64)
    one = np.array([[0, 1]], dtype=np.int64)
    # An edge forms at <= link range ...
    assert graph_edges(line([0, 40.0]), active, none, LINK).tolist() == [[0, 1]]
    # ... does not form in the hysteresis band if it did not exist ...
    assert graph_edges(line([0, 41.0]), active, none, LINK).shape == (0, 2)
    # ... is kept in the band (link, link + 2 m] once made ...
    assert graph_edges(line([0, 41.0]), active, one, LINK).tolist() == [[0, 1]]
    assert graph_edges(line([0, 42.0]), active, one, LINK).tolist() == [[0, 1]]
    # ... and breaks beyond link + 2 m.
    assert graph_edges(line([0, 42.01]), active, one, LINK).shape == (0, 2)
    # Inactive agents have no edges.
    assert graph_edges(line([0, 10.0]), np.array([True, False]), one, LINK).shape == (0, 2)


@settings(max_examples=80, deadline=None)
@given(st.integers(2, 40), st.integers(0, 2**32 - 1))
def test_labels_are_connected_components(n, seed):
    rng = np.random.default_rng(seed)
    p = rng.uniform(0, 150, (n, 2))
    active = rng.random(n) < 0.9
    edges = graph_edges(p, active, np.zeros((0, 2), np.int64), LINK)
    lab = labels(n, edges, active)
    # Reference: flood fill over the same edges.
    adj: dict[int, set[int]] = {i: set() for i in range(n)}
    for a, b in edges.tolist():
        adj[a].add(b)
        adj[b].add(a)
    for i in range(n):
        if not active[i]:
            assert lab[i] == -1
            continue
        seen, stack = {i}, [i]
        while stack:
            for j in adj[stack.pop()]:
                if j not in seen:
                    seen.add(j)
                    stack.append(j)
        assert lab[i] == min(seen)  # label: the smallest index of the group
        assert {j for j in range(n) if lab[j] == lab[i]} == seen
    g = groups_of(lab, np.arange(100, 100 + n))
    assert sorted(x for grp in g for x in grp) == [100 + i for i in range(n) if active[i]]


def test_labels_large_graph_path_agrees_with_small():
    rng = np.random.default_rng(2)
    n = 400  # a large graph: many rounds of hooking and pointer jumping
    p = rng.uniform(0, 1500, (n, 2))
    act = np.ones(n, dtype=bool)
    edges = graph_edges(p, act, np.zeros((0, 2), np.int64), LINK)
    lab = labels(n, edges, act)
    for a, b in edges.tolist():
        assert lab[a] == lab[b]
    assert all(lab[i] <= i for i in range(n))
    assert len(set(lab.tolist())) == len({int(x) for x in lab})


# ------------------------------------------------------------------------------------------ events


def test_split_confirmed_after_one_second_and_timed_at_the_change():
    together = line([0, 30, 60, 90])
    apart = line([0, 30, 120, 150])  # 2-3 gap 90 m: {1, 2} | {3, 4}
    seq = hold(together, 2.0) + hold(apart, 3.0)
    t_change = round(len(hold(together, 2.0)) * DT, 9)
    events, tr = run_tracker(seq)
    assert len(events) == 1
    t_conf, ev = events[0]
    assert ev["kind"] == "split"
    assert ev["t"] == pytest.approx(t_change)  # timed at the change ...
    assert t_conf == pytest.approx(t_change + 1.0)  # ... recorded once it held 1 s, not before
    assert ev["before"] == [[1, 2, 3, 4]]
    assert ev["after"] == [[1, 2], [3, 4]]
    assert tr.n_groups == 2
    # Held for 0.95 s (ticks at +0, ..., +0.95): not enough; the tick at +1.0 s confirms it.
    short, _ = run_tracker(hold(together, 2.0) + [apart] * 20)
    assert short == []
    exact, _ = run_tracker(hold(together, 2.0) + [apart] * 21)
    assert [(t, e["kind"]) for t, e in exact] == [(pytest.approx(t_change + 1.0), "split")]


def test_flicker_shorter_than_one_second_gives_no_event():
    together = line([0, 30, 60])
    apart = line([0, 30, 100])
    seq = hold(together, 2.0) + hold(apart, 0.95) + hold(together, 2.0) + hold(apart, 0.5) + hold(together, 1.0)
    events, _ = run_tracker(seq)
    assert events == []


def test_merge_with_groups_before_and_after():
    apart = line([0, 30, 120, 150, 300])
    together = line([0, 30, 60, 90, 300])
    seq = hold(apart, 1.5) + hold(together, 1.5)
    events, _ = run_tracker(seq, ids=[7, 3, 9, 1, 5])
    assert [e["kind"] for _, e in events] == ["merge"]
    ev = events[0][1]
    assert ev["t"] == pytest.approx(1.5)
    assert ev["before"] == [[1, 9], [3, 7]]  # groups sorted inside and by their smallest member
    assert ev["after"] == [[1, 3, 7, 9]]


def test_split_then_merge_and_new_grouping_restarts_the_clock():
    a = line([0, 30, 60, 90])
    b = line([0, 30, 120, 150])
    c = line([0, 100, 130, 160])  # {1} | {2, 3, 4}: a different split, pending restarts at its own time
    seq = hold(a, 1.0) + hold(b, 0.5) + hold(c, 2.0) + hold(a, 2.0)
    events, _ = run_tracker(seq)
    kinds = [(e["kind"], e["before"], e["after"]) for _, e in events]
    assert kinds == [("split", [[1, 2, 3, 4]], [[1], [2, 3, 4]]), ("merge", [[1], [2, 3, 4]], [[1, 2, 3, 4]])]
    assert events[0][1]["t"] == pytest.approx(1.5)
    assert events[1][1]["t"] == pytest.approx(3.5)


def test_hysteresis_keeps_a_group_in_the_band():
    seq = hold(line([0, 40.0]), 1.0) + hold(line([0, 41.9]), 3.0)  # stretched into the band: still one group
    events, tr = run_tracker(seq)
    assert events == [] and tr.n_groups == 1
    seq += hold(line([0, 42.5]), 1.5)  # beyond link + 2 m: split
    events, _ = run_tracker(seq)
    assert [e["kind"] for _, e in events] == ["split"]
    # Approaching again: no merge in the band, merge at link range.
    seq2 = hold(line([0, 50.0]), 1.0) + hold(line([0, 41.0]), 2.0)
    assert run_tracker(seq2)[0] == []
    seq2 += hold(line([0, 39.0]), 1.5)
    assert [e["kind"] for _, e in run_tracker(seq2)[0]] == ["merge"]


def test_many_to_many_change():
    # {1, 2} {3, 4} -> {1, 3} {2, 4}: a split of each group into its parts, then a merge of the parts.
    old = (frozenset({1, 2}), frozenset({3, 4}))
    new = (frozenset({1, 3}), frozenset({2, 4}))
    got = diff(old, new)
    assert sorted(got) == sorted([
        ("split", [[1, 2]], [[1], [2]]), ("split", [[3, 4]], [[3], [4]]),
        ("merge", [[1], [3]], [[1, 3]]), ("merge", [[2], [4]], [[2, 4]]),
    ])
    # The same through the tracker, with positions.
    p_old = np.array([[0, 0], [30, 0], [0, 200], [30, 200]], dtype=float)
    p_new = np.array([[0, 0], [0, 200], [0, 30], [0, 230]], dtype=float)
    events, _ = run_tracker(hold(p_old, 1.0) + hold(p_new, 1.5))
    assert sorted((e["kind"], e["before"], e["after"]) for _, e in events) == sorted(got)
    assert all(e["t"] == pytest.approx(1.0) for _, e in events)


def test_diff_ignores_agents_not_present_in_both():
    old = (frozenset({1, 2, 3}),)
    new = (frozenset({1, 2}),)  # agent 3 left (membership, not topology)
    assert diff(old, new) == []
    assert diff((frozenset({1, 2}), frozenset({3})), (frozenset({1}), frozenset({2}), frozenset({3}))) == [
        ("split", [[1, 2]], [[1], [2]])]
    assert diff((), (frozenset({1}),)) == []


def test_inactive_agent_leaves_without_a_split():
    p = line([0, 30, 60])
    act_all = [[True, True, True]] * 20
    act_gone = [[True, False, True]] * 40  # the middle agent dies: 1 and 3 are 60 m apart
    events, tr = run_tracker([p] * 60, active=act_all + act_gone)
    # The group {1, 3} divided because 2 vanished: that is a split of the common agents {1, 3}.
    assert [(e["kind"], e["before"], e["after"]) for _, e in events] == [("split", [[1, 3]], [[1], [3]])]
    assert tr.n_groups == 2


# ------------------------------------------------------------------------------------------ safety


def test_safety_monitor_gaps_and_episodes():
    ids = np.array([1, 2, 3])
    radii = np.array([1.0, 2.0, 1.5])
    mon = SafetyMonitor(ids, radii, ("box",), d_safe_m=2.0)
    # Agent 2 approaches agent 1 along x: centre distances 10, 4.5 (gap 1.5: safety), 2.5 (gap -0.5: contact),
    # 4.5, 10 (apart), then 2.9 again (a second contact episode).
    xs = [10.0, 4.5, 2.5, 4.5, 10.0, 2.9]
    all_started, all_ended = [], []
    for k, x in enumerate(xs):
        p = np.array([[0.0, 0.0], [x, 0.0], [100.0, 100.0]])
        ob_d = np.array([[50.0], [50.0], [3.0 if k == 3 else 20.0]])  # agent 3 brushes the box at k = 3
        gap_a, gap_o, started, ended = mon.step(k * 0.5, p, ob_d)
        assert gap_a == pytest.approx(min(x - 3.0, math.hypot(100, 100) - 2.5))
        assert gap_o == pytest.approx(min(50.0 - 2.0, (3.0 if k == 3 else 20.0) - 1.5))
        all_started += [(k, e.kind, e.a, e.b) for e in started]
        all_ended += [(k, *key) for key in ended]
    assert all_started == [
        (1, "safety", "agent:1", "agent:2"),
        (2, "collision", "agent:1", "agent:2"),
        (3, "safety", "agent:3", "obstacle:box"),
        (5, "safety", "agent:1", "agent:2"),
        (5, "collision", "agent:1", "agent:2"),
    ]
    assert (3, "collision", "agent:1", "agent:2") in all_ended
    assert (4, "safety", "agent:1", "agent:2") in all_ended
    assert (4, "safety", "agent:3", "obstacle:box") in all_ended
    assert mon.min_agent_gap_m == pytest.approx(-0.5)
    assert mon.min_obstacle_gap_m == pytest.approx(1.5)


def test_safety_monitor_min_gap_when_everything_is_far():
    # A (r 5) at 0, C (r 5) at -31: gap 21. But C's nearest centre is D (r 1, 30.5 away, gap 24.5) and A's is
    # B (r 1, 30.9 away, gap 24.9): nobody's nearest centre is the closest surface.
    p = np.array([[0.0, 0.0], [30.9, 0.0], [-31.0, 0.0], [-61.5, 0.0]])
    r = np.array([5.0, 1.0, 5.0, 1.0])
    mon = SafetyMonitor(np.array([1, 2, 3, 4]), r, (), d_safe_m=2.0)
    gap_a, _, _, _ = mon.step(0.0, p, np.zeros((4, 0)))
    true_min = min(math.dist(p[i], p[j]) - r[i] - r[j] for i in range(4) for j in range(i + 1, 4))
    assert true_min == pytest.approx(21.0)
    assert gap_a == pytest.approx(true_min)


@pytest.mark.parametrize("seed", range(5))
def test_edge_changes_between_two_sorted_key_sets(seed):
    """_changes gives exactly the set differences (sorted) of two sorted, unique key arrays."""
    rng = np.random.default_rng(seed)
    old = np.unique(rng.integers(0, 400, int(rng.integers(0, 200))))
    new = np.unique(np.concatenate([rng.choice(old, old.size // 2, replace=False) if old.size else old,
                                    rng.integers(0, 400, int(rng.integers(0, 50)))])).astype(np.int64)
    added, removed = _changes(old.astype(np.int64), new)
    assert added.tolist() == np.setdiff1d(new, old).tolist()
    assert removed.tolist() == np.setdiff1d(old, new).tolist()


@pytest.mark.parametrize("seed", range(6))
def test_nearest_gap_is_the_smallest_surface_gap_of_all_pairs(seed):
    """nearest_gap (used when no pair is close) equals the brute-force minimum of ‖p_i - p_j‖ - r_i - r_j over
    every ordered pair, for swarms spread over 1 m to 1000 km, and ignores unknown (NaN) positions."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 120))
    p = rng.uniform(-1e3, 1e3, (n, 2)) * [1e-3, 1.0, 1e3][seed % 3]
    r = rng.uniform(0.5, 5.0, n)
    if seed % 2:
        p[0] = np.nan
    want = min(math.hypot(*(p[i] - p[j])) - r[i] - r[j] for i in range(n) for j in range(n)
               if i != j and np.isfinite(p[i]).all() and np.isfinite(p[j]).all())
    assert nearest_gap(p, r) == pytest.approx(want, rel=1e-12, abs=1e-9)
