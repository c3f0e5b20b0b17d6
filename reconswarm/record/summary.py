"""The run summary (its fields: docs/wire.md), computed from a run record alone."""

from __future__ import annotations

from typing import Any

import numpy as np

from reconswarm.record.extra import trusted
from reconswarm.record.store import RunRecord

FIELDS = ("scenario", "planner", "mode", "agents", "duration_s", "converged", "convergence_time_s",
          "final_max_error_m", "min_agent_gap_m", "min_obstacle_gap_m", "collisions", "safety_violations",
          "splits", "merges", "agents_lost", "messages_rejected", "intrusions", "path_length_m", "wall_time_s")


def _r(v: float | None, nd: int = 3) -> float | None:
    if v is None or not np.isfinite(v):
        return None
    return round(float(v), nd)


def lost_agents(events: list[dict[str, Any]]) -> list[int]:
    """Agents whose last membership event is agent_lost."""
    last: dict[int, str] = {}
    for e in events:
        if e["kind"] in ("agent_lost", "agent_joined") and "agent" in e:
            last[int(e["agent"])] = e["kind"]
    return sorted(a for a, k in last.items() if k == "agent_lost")


def distinct_intrusions(rows: list[dict[str, Any]]) -> tuple[dict[str, int], dict[str, int]]:
    """(refused messages per kind, each counted once per run; refusals per receiving process).

    Every process counts what it refuses, per kind and source, so one forged message heard by ten processes
    (a clock: the monitor and every agent) is ten refusals but one message. Per kind and source, the
    messages are the most any one process refused: those that reached several processes are counted once
    (a process that heard only some of them, an agent that came later, counts fewer, never more)."""
    most: dict[tuple[str, str], int] = {}
    by_process: dict[str, int] = {}
    for row in rows:
        k, n = (row["kind"], row["source"]), int(row["count"])
        most[k] = max(most.get(k, 0), n)
        by_process[row["process"]] = by_process.get(row["process"], 0) + n
    by_kind: dict[str, int] = {}
    for (kind, _source), n in sorted(most.items()):
        by_kind[kind] = by_kind.get(kind, 0) + n
    return by_kind, by_process


def convergence_time(t: np.ndarray, max_err: np.ndarray, tol: float) -> float | None:
    """Start of the final stretch with every live agent within tol, if the run ends inside it."""
    if max_err.size == 0 or not (max_err[-1] <= tol):
        return None
    above = np.flatnonzero(~(max_err <= tol))
    return float(t[above[-1] + 1]) if above.size else float(t[0])


def summarize(rec: RunRecord) -> dict[str, Any]:
    s = rec.scenario
    tk = rec.ticks()
    events = rec.events()
    contacts = rec.contacts()
    tol = s.planner.converge_tol_m
    err = tk.max_error_m
    conv_t = convergence_time(tk.t, err, tol)
    converged = conv_t is not None
    if tk.t.size > 1:
        step = np.sqrt(np.diff(tk.px, axis=0) ** 2 + np.diff(tk.py, axis=0) ** 2)
        path = np.nansum(step, axis=0)
    else:
        path = np.zeros(len(rec.ids))
    counters = rec.counters()
    intrusions = rec.intrusions()
    by_kind, by_process = distinct_intrusions(intrusions)
    wall = rec.meta.get("wall_time_s")
    out: dict[str, Any] = {
        "scenario": rec.meta.get("scenario", s.meta.name),
        "planner": rec.meta.get("planner", s.planner.kind.value),
        "mode": rec.meta.get("mode"),
        "agents": len(rec.ids),
        "duration_s": _r(float(tk.t[-1]) if tk.t.size else 0.0),
        "converged": converged,
        "convergence_time_s": _r(conv_t),
        "final_max_error_m": _r(float(err[-1]) if err.size else None),
        "min_agent_gap_m": _r(float(np.nanmin(tk.min_agent_gap_m)) if np.isfinite(tk.min_agent_gap_m).any() else None),
        "min_obstacle_gap_m": _r(float(np.nanmin(tk.min_obstacle_gap_m))
                                 if np.isfinite(tk.min_obstacle_gap_m).any() else None),
        "collisions": sum(1 for c in contacts if c["kind"] == "collision"),
        "safety_violations": sum(1 for c in contacts if c["kind"] == "safety"),
        "splits": sum(1 for e in events if e["kind"] == "split"),
        "merges": sum(1 for e in events if e["kind"] == "merge"),
        "agents_lost": lost_agents(events),
        "messages_rejected": int(sum(counters.values())),
        "intrusions": int(sum(by_kind.values())),
        "path_length_m": {str(int(i)): _r(float(v), 2) for i, v in zip(rec.ids, path, strict=True)},
        "wall_time_s": _r(float(wall)) if wall is not None else None,
        # Beyond the documented fields:
        "seed": s.meta.seed,
        "ticks": int(tk.k.size),
        "finished": rec.meta.get("finished") == "1",
        "messages_rejected_by_process": counters,
        "record_gaps": rec.gaps(),
        "intrusions_by_kind": by_kind,
        "intrusions_by_process": by_process,
        "intrusion_sources": sorted({row["source"] for row in intrusions}),
        # The engine is deterministic; lockstep is unless an agent acted without all of a tick's data (the
        # monitor's extra below says so, with the simulated time it happened); realtime is not, by design.
        "deterministic": rec.meta.get("mode") == "inprocess",
        "determinism_lost_at_s": None,
    }
    extra = rec.meta_json("extra", {})
    if isinstance(extra, dict):  # (only what its writers may add, checked: never a field computed above)
        out.update(trusted(extra, out))
    return out


def render(summary: dict[str, Any]) -> Any:
    """A rich Table of the summary (path lengths condensed)."""
    from rich.table import Table

    table = Table(title=f"reconswarm run: {summary['scenario']} ({summary['planner']}, {summary['mode']})",
                  show_header=True)
    table.add_column("field")
    table.add_column("value", overflow="fold")
    for key, val in summary.items():
        if key == "messages_rejected_by_process":
            val = {k: v for k, v in val.items() if v}
        if key in ("path_length_m", "messages_rejected_by_process", "record_gaps", "intrusions_by_kind",
                   "intrusions_by_process", "intrusion_sources"):
            if isinstance(val, dict) and val:
                nums = [v for v in val.values() if isinstance(v, int | float)]
                if key == "path_length_m" and nums:
                    val = f"min {min(nums):.1f}, mean {sum(nums) / len(nums):.1f}, max {max(nums):.1f} m"
            elif not val:
                continue
        if key == "deterministic" and summary.get("mode") == "realtime":
            val = "not claimed (realtime runs on wall time)"  # realtime is not deterministic, by design
        elif key == "determinism_lost_at_s" and val is None:
            continue  # nothing was lost (or, in realtime, nothing was claimed)
        if isinstance(val, bool):
            val = "[green]yes[/green]" if val else "[red]no[/red]"
        table.add_row(key, "-" if val is None else str(val))
    return table
