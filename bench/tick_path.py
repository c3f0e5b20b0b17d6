#!/usr/bin/env python3
"""Where a lockstep tick's wall time goes: the serial path of one run, segment by segment.

Each tick the world puts its clock and every robot's state; a state reaches its agent's process (its host); the
host puts each of its agents' beacons; the beacons of agents in other processes come back; the host plans and
puts the commands; the commands reach the world, which steps the robots and puts the next tick. The run's
processes stamp each put and each arrival with the monotonic clock (reconswarm/net/runtime/trace.py, on while
RECONSWARM_TRACE_DIR names a directory); this script runs the mission with that on and prints each segment's
median and mean over the ticks (past the first `--skip-ticks`) and the hosts, one column per
`--agents-per-process` value, with the run's wall time and the tracing's own cost left in it (a row per mark).
Made for lockstep; in realtime the world does not wait, so its last segment is negative for a command that came
after the next tick. ROS 2 mode is not marked (its odometry and cmd_vel travel on ROS 2 topics).

    .venv/bin/python bench/tick_path.py                              # the paper at K = 5
    .venv/bin/python bench/tick_path.py --agents-per-process 1 5 10
    .venv/bin/python bench/tick_path.py -- --clock realtime --speed 10   # anything after -- goes to the launcher
"""

from __future__ import annotations

import _venv  # noqa: F401  (first: the project's .venv, re-run there if this Python lacks it)

# isort: split
import argparse
import os
import statistics
import sys
import tempfile
from collections import defaultdict
from collections.abc import Iterable, Mapping
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import command_line, machine, median
from bench_deploy import PAPER, free_port, launch

from reconswarm.net.runtime.trace import ENV, Mark

Events = dict[tuple[str, int], dict[int, float]]  # (mark, tick) -> agent -> seconds (the first, if several)

KINDS = {"world": "the world computing", "host": "a host computing", "hop": "samples travelling (and waits)"}
SEGMENTS = {  # key -> (what it measures, its kind); the kinds' sums are a rough split of a tick, not its median
    "world_puts": ("world: clock put -> last state put", "world"),
    "state_hop": ("state: put -> arrival in its host", "hop"),
    "to_beacons": ("host: last own state in -> last own beacon put", "host"),
    "beacon_wait": ("host: last own beacon put -> last beacon of another process in (0: in already)", "hop"),
    "to_commands": ("host: beacons in -> last command put", "host"),
    "command_hop": ("command: put -> arrival in the world", "hop"),
    "world_step": ("world: last command in -> next clock put", "world"),
    "tick": ("tick: clock put -> next clock put", "tick"),
    "beacon_hop": ("beacon: put -> arrival in another process (beside the path)", "beside"),
}


def read(directory: Path) -> dict[int, Events]:
    """Each process's marks (by pid) from the trace files in `directory`."""
    out: dict[int, Events] = {}
    for path in directory.glob("*.tsv"):
        ev: Events = defaultdict(dict)
        for line in path.read_text().splitlines():
            what, k, agent, t = line.split("\t")
            ev[(what, int(k))].setdefault(int(agent), float(t))
        out[int(path.stem)] = ev
    return out


def roles(marks: Mapping[int, Events]) -> tuple[list[Events], dict[int, Events]]:
    """The processes' marks as (the world's: those that put clocks, one in a run; the hosts': pid -> marks of those
    that took their agents' states)."""
    worlds = [ev for ev in marks.values() if any(what == Mark.CLOCK_PUT.value for what, _k in ev)]
    hosts = {pid: ev for pid, ev in marks.items() if any(what == Mark.STATE_IN.value for what, _k in ev)}
    return worlds, hosts


def segments(world: Events, hosts: Mapping[int, Events], ticks: Iterable[int]) -> dict[str, list[float]]:
    """Each segment's durations in seconds (by its key in SEGMENTS) over the ticks and, for the hosts' segments, over
    the hosts (pid -> its marks; a host's agents are those whose states it took). A tick missing a mark is left out
    of the segments that need it."""
    out: dict[str, list[float]] = {key: [] for key in SEGMENTS}
    for k in ticks:
        clock, clock_next = world.get((Mark.CLOCK_PUT.value, k), {}), world.get((Mark.CLOCK_PUT.value, k + 1), {})
        states, cmds_in = world.get((Mark.STATE_PUT.value, k), {}), world.get((Mark.CMD_IN.value, k), {})
        if not clock or not states:
            continue
        out["world_puts"].append(max(states.values()) - clock[0])
        if clock_next:
            out["tick"].append(clock_next[0] - clock[0])
            if cmds_in:
                out["world_step"].append(clock_next[0] - max(cmds_in.values()))
        put = {a: t for ev in hosts.values() for a, t in ev.get((Mark.BEACON_PUT.value, k), {}).items()}
        for ev in hosts.values():
            got = ev.get((Mark.STATE_IN.value, k), {})
            beacons = ev.get((Mark.BEACON_PUT.value, k), {})
            others = ev.get((Mark.BEACON_IN.value, k), {})
            cmds = ev.get((Mark.CMD_PUT.value, k), {})
            if not got or not beacons or not cmds:
                continue
            out["state_hop"].append(median([got[a] - states[a] for a in got if a in states]))
            out["to_beacons"].append(max(beacons.values()) - max(got.values()))
            ready = max(beacons.values())
            if others:
                last_in = max(others.values())
                out["beacon_wait"].append(max(0.0, last_in - ready))
                ready = max(ready, last_in)
                if hops := [t - put[a] for a, t in others.items() if a in put]:
                    out["beacon_hop"].append(median(hops))
            out["to_commands"].append(max(cmds.values()) - ready)
            if arrived := [cmds_in[a] - cmds[a] for a in cmds if a in cmds_in]:
                out["command_hop"].append(median(arrived))
    return out


def run(k: str, scenario: Path, skip: int, extra: list[str]) -> tuple[dict[str, list[float]], dict]:
    with tempfile.TemporaryDirectory(prefix="tick-path-") as tmp:
        trace_dir = Path(tmp) / "trace"
        trace_dir.mkdir()
        os.environ[ENV] = str(trace_dir)
        try:
            summary = launch(Path(tmp) / "run", scenario, free_port(), "--agents-per-process", k, *extra)
        finally:
            del os.environ[ENV]
        marks = read(trace_dir)
    worlds, hosts = roles(marks)
    return segments(worlds[0] if worlds else {}, hosts, range(skip, int(summary["ticks"]) - 1)), summary


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", type=Path, default=PAPER)
    ap.add_argument("--agents-per-process", nargs="+", default=["5"], metavar="K")
    ap.add_argument("--skip-ticks", type=int, default=100, help="ticks left out at the start (start-up)")
    ap.add_argument("launcher_args", nargs="*", help="after --: more options for the launcher (run_local.sh's)")
    a = ap.parse_args()
    print(machine())
    print(command_line())
    got = {k: run(k, a.scenario, a.skip_ticks, a.launcher_args) for k in a.agents_per_process}
    head = "".join(f" | K = {k:>4} p50 / mean ms" for k in got)
    print(f"{'segment':80s}{head}")
    for key, (label, _kind) in SEGMENTS.items():
        cells = "".join(f" | {median(x) * 1e3:9.3f} / {statistics.mean(x) * 1e3:6.3f}" if (x := seg[key])
                        else f" | {'-':>18s}" for seg, _ in got.values())
        print(f"{label:80s}{cells}")
    for kind, says in KINDS.items():
        keys = [key for key, (_label, of) in SEGMENTS.items() if of == kind]
        sums = "".join(f" | {sum(median(seg[key]) for key in keys if seg[key]) * 1e3:18.3f}" for seg, _ in got.values())
        print(f"{'sum of the medians: ' + says:80s}{sums}")
    for k, (_seg, summary) in got.items():
        missed = summary.get("missed_deadline_ratio")
        print(f"K = {k}: {summary['ticks']} ticks, {summary['wall_time_s']:.2f} s of wall "
              f"({summary['duration_s'] / summary['wall_time_s']:.1f}x real time), collisions {summary['collisions']}, "
              f"deterministic {summary['deterministic']}" + ("" if missed is None else f", {missed:.1%} missed"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
