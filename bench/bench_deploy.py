#!/usr/bin/env python3
"""The distributed deployment, measured with real processes through deploy/run_local.sh's launcher:

1. lockstep on a sparse grid (bench/grid.py: about 8 neighbours per agent whatever N is) for N = 16, 36,
   64, 100: CPU-ms per tick per role (from each process's exit line, as the difference between a run and
   one a third as long, so start-up does not count), messages received and loop wake-ups per agent per
   tick, simulated seconds per wall second;
2. the paper mission in lockstep (--paper): sim/wall until it converges;
   beside them the floor (bench/floor.py): the same message pattern with msgpack only and no planning,
   `floor-cells` (the spatial cells) and `floor-all` (every beacon to everyone), in the same run;
3. realtime at --speed 1 (the control loop at 1/dt = 20 Hz): the largest N whose missed-deadline ratio
   stays below 1 %, trying N in increasing order;
4. lockstep = in-process (--equal-agents N): the grid of N agents in lockstep against `reconswarm sim` on
   the same scenario, the largest difference of any head point or heading at any tick, optionally with
   --equal-load busy processes running meanwhile (other work on the machine); --equal-paper: the paper
   mission likewise, until it converges.
5. large swarms (--large-agents 400): the grid in lockstep until its duration: finished, sim/wall, collisions,
   agents lost, the peak RSS of the run's processes summed and over N;
6. the paper at --clock realtime --speed X (--paper-realtime X): converged, missed-deadline ratio, collisions,
   plain, with kill:agent:3@60 and with flood@30;
7. the paper in ROS 2 mode at --speed X (--paper-ros2 X): the same, plain and with kill:agent:3@60, with the
   state-to-command latency and the CPU of all the run's processes.
`--agents-per-process K ...` (default 1) measures each row with K agents per process (agent hosts; `auto`
too), side by side; an agent host's CPU, messages and wake-ups count a K-th to each of its agents.
`--checkout DIR` (repeatable) measures another checkout (a git worktree of an older commit with its own
.venv) in the same run, row by row beside this one (at each K if it has agent hosts).

    .venv/bin/python bench/bench_deploy.py --paper
    .venv/bin/python bench/bench_deploy.py --paper --equal-paper --agents-per-process 1 5 10 --grid-agents
    .venv/bin/python bench/bench_deploy.py --grid-agents --realtime-agents --large-agents 400 --agents-per-process auto
    .venv/bin/python bench/bench_deploy.py --grid-agents --realtime-agents --paper-realtime 10 --agents-per-process 5
    .venv/bin/python bench/bench_deploy.py --grid-agents --realtime-agents --paper-ros2 4 --agents-per-process 1 5 auto
    .venv/bin/python bench/bench_deploy.py --quick
"""

from __future__ import annotations

import _venv  # noqa: F401  (first: the project's .venv, re-run there if this Python lacks it)

# isort: split
import argparse
import ast
import json
import re
import socket
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import numpy as np
from _common import command_line, machine, median
from floor import PATTERNS, floor_run
from grid import grid_scenario

from agent.process import parse_ids
from reconswarm.record.store import RunRecord
from reconswarm.scenario.model import to_toml

ROOT = Path(__file__).resolve().parent.parent
PAPER = ROOT / "deploy" / "scenarios" / "paper.toml"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def launch(out: Path, scen: Path, port: int, *extra: str, timeout: float = 1800,
           launcher: tuple[list[str], Path] | None = None) -> dict:
    cmd, cwd = launcher or ([sys.executable, "-m", "reconswarm_bringup.cli_launch"], ROOT)
    p = subprocess.run([*cmd, "--router", f"tcp/127.0.0.1:{port}", "-o", str(out), "-s", str(scen), "--no-progress",
                        "--json", *extra], capture_output=True,
                       text=True, timeout=timeout, cwd=cwd)
    if p.returncode not in (0, 1):
        raise RuntimeError(f"run failed ({p.returncode}): {p.stderr[-1500:]}")
    return json.loads(p.stdout)


def exit_lines(out: Path) -> dict[Path, dict[str, float]]:
    """Each process's exit line `usage: {...}` (CPU seconds, peak RSS, and messages in where logged), by its log
    (a process killed by SIGKILL writes none)."""
    return {log: ast.literal_eval(m[-1]) for log in (out / "logs").glob("*.log")
            if (m := re.findall(r"usage: (\{.*\})", log.read_text(errors="replace")))}


def role_usage(out: Path) -> dict[str, list[dict[str, float]]]:
    """The exit lines by role; an agent host's (logs/agent-1-5.log) as a K-th of it for each of its K agents (peak
    RSS: the host's)."""
    roles: dict[str, list[dict[str, float]]] = {}
    for log, use in exit_lines(out).items():
        role, _, ids = log.stem.partition("-")
        k = len(parse_ids(None, ids)) if role == "agent" else 1
        share = {key: (v if key == "max_rss_mb" else v / k) for key, v in use.items()}
        roles.setdefault(role, []).extend([share] * k)
    return roles


def peak_rss_mb(out: Path) -> tuple[float, int]:
    """The sum over the run's processes of each one's peak RSS (its exit line), and how many processes logged one."""
    rss = [use.get("max_rss_mb", 0.0) for use in exit_lines(out).values()]
    return float(sum(rss)), len(rss)


def cpu_s(out: Path) -> tuple[float, int]:
    """CPU seconds (user + sys) of all the run's processes, from their exit lines, and how many logged one."""
    uses = exit_lines(out).values()
    return float(sum(use["cpu_user_s"] + use["cpu_sys_s"] for use in uses)), len(uses)


def has_option(checkout: Path, option: str) -> bool:
    """Does that checkout's launcher take `option`?"""
    cli = checkout / "reconswarm_bringup" / "cli_launch.py"
    return cli.exists() and option in cli.read_text()


def hosts_agents(checkout: Path) -> bool:
    """Has that checkout agent hosts (`--agents-per-process`)?"""
    return has_option(checkout, "--agents-per-process")


def launcher_cmd(checkout: Path | None) -> tuple[list[str], Path]:
    """How to start run_local.sh's launcher: this checkout's, or another one's (its own .venv), so an older
    version is measured in the same run on the same machine."""
    if checkout is None:
        return [sys.executable, "-m", "reconswarm_bringup.cli_launch"], ROOT
    py = str(checkout / ".venv" / "bin" / "python")
    new = (checkout / "reconswarm_bringup" / "cli_launch.py").exists()
    return [py, "-m", "reconswarm_bringup.cli_launch" if new else "reconswarm.launcher"], checkout


def grid_run(tmp: Path, n: int, sim_s: float, checkout: Path | None,
             extra: tuple[str, ...] = ()) -> tuple[int, float, dict[str, list[dict]]]:
    """One lockstep grid run: (ticks, sim/wall, each process's exit line by role)."""
    scen = tmp / f"grid{n}-{sim_s:g}.toml"
    scen.write_text(to_toml(grid_scenario(n, sim_s)))
    out = tmp / f"grid{n}-{sim_s:g}-{'old' if checkout else 'new'}-{len(str(checkout))}-{'-'.join(extra)}"
    s = launch(out, scen, free_port(), *extra, launcher=launcher_cmd(checkout))
    return round(s["duration_s"] / 0.05) + 1, s["duration_s"] / s["wall_time_s"], role_usage(out)


def grid_row(tmp: Path, n: int, sim_s: float, checkout: Path | None, extra: tuple[str, ...] = ()) -> dict[str, float]:
    """Per-tick figures as the difference of a run of sim_s and one of sim_s / 3: start-up (imports, sessions,
    the start barrier) cancels out, whatever the version logs."""
    t_short, _, short = grid_run(tmp, n, sim_s / 3, checkout, extra)
    ticks_long, sim_wall, long = grid_run(tmp, n, sim_s, checkout, extra)
    ticks = ticks_long - t_short

    def per_tick(role: str, key: str, agg: str = "sum") -> float:
        def vals(use: dict[str, list[dict]]) -> list[float]:
            return [(u["cpu_user_s"] + u["cpu_sys_s"]) if key == "cpu" else u[key]
                    for u in use.get(role, []) if key == "cpu" or key in u]
        a, b = vals(long), vals(short)
        if not a or not b:
            return float("nan")
        f = sum if agg == "sum" else median
        return (f(a) - f(b)) / ticks

    return {"n": n, "ticks": ticks, "sim_wall": sim_wall,
            "agent_ms": 1000 * per_tick("agent", "cpu", "median"),
            "agents_ms": 1000 * per_tick("agent", "cpu"),
            "world_ms": 1000 * per_tick("simworld", "cpu"),
            "monitor_ms": 1000 * per_tick("monitor", "cpu"),
            "router_ms": 1000 * per_tick("router", "cpu"),
            "msgs_in": per_tick("agent", "msgs_in", "median"),
            "wakeups": per_tick("agent", "wakeups", "median")}


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "reconswarm_bringup.cli", *args], capture_output=True, text=True,
                          cwd=ROOT, timeout=1800)


def poses(db: Path) -> tuple[list[int], list[int], np.ndarray]:
    """A run's record as (ticks, agent ids, poses (T, N, 3): px, py, theta), read with RunRecord."""
    with RunRecord(db) as rec:
        tk = rec.ticks()
        return tk.k.tolist(), list(rec.ids), np.stack([tk.px, tk.py, tk.theta], axis=-1)


def equal_run(tmp: Path, n: int | None, sim_s: float, load: int, extra: tuple[str, ...] = ()) -> str:
    """The grid of n agents (None: the paper mission) in lockstep and in process, with `load` busy processes
    meanwhile: one line."""
    name = f"equal{n or 'paper'}"
    if n is None:
        scen = PAPER
    else:
        scen = tmp / f"{name}.toml"
        scen.write_text(to_toml(grid_scenario(n, sim_s)))
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(load)]
    out = tmp / f"{name}-{'-'.join(extra)}"
    try:
        s = launch(out, scen, free_port(), *extra)
    finally:
        for b in busy:
            b.kill()
            b.wait()
    if not (tmp / f"{name}-sim" / "run.db").exists():
        sim = cli("sim", str(scen), "-o", str(tmp / f"{name}-sim"), "--json")
        if sim.returncode not in (0, 1):
            raise RuntimeError(f"sim failed: {sim.stderr[-500:]}")
        (tmp / f"{name}-sim" / "summary.json").write_text(sim.stdout)
    ref_s = json.loads((tmp / f"{name}-sim" / "summary.json").read_text())
    (k, ids, got), (k_ref, ids_ref, ref) = poses(out / "run.db"), poses(tmp / f"{name}-sim" / "run.db")
    who = f"N = {n}" if n is not None else "paper"
    if (k, ids) != (k_ref, ids_ref):
        return f"{who} {' '.join(extra)}: different ticks or agents ({got.shape} against {ref.shape})"
    diff = float(np.abs(got - ref).max())
    rate = s["duration_s"] / s["wall_time_s"]
    return (f"{who} {' '.join(extra) or '(1 agent per process)'}, {s['ticks']} ticks, {load} busy processes "
            f"meanwhile: deterministic {s['deterministic']}, converged at {s['convergence_time_s']} s (sim: "
            f"{ref_s['convergence_time_s']} s), largest difference {diff:g} m (or rad) over "
            f"{got.shape[0] * got.shape[1]} poses, sim/wall {rate:.2f}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--grid-agents", type=int, nargs="*", default=[16, 36, 64, 100])
    ap.add_argument("--grid-sim-s", type=float, default=10.0, help="simulated seconds per grid run")
    ap.add_argument("--floor", nargs="*", choices=PATTERNS, default=list(PATTERNS),
                    help="floor rows per N (bench/floor.py); none with an empty list")
    ap.add_argument("--checkout", type=Path, action="append", default=[],
                    help="also measure another checkout (a git worktree with its own .venv), side by side")
    ap.add_argument("--paper", action="store_true", help="also time the whole paper mission in lockstep")
    ap.add_argument("--realtime-agents", type=int, nargs="*", default=[16, 36, 64, 100])
    ap.add_argument("--realtime-sim-s", type=float, default=20.0, help="simulated (= wall) seconds per run")
    ap.add_argument("--equal-agents", type=int, nargs="*", default=[], help="lockstep = in-process on the grid")
    ap.add_argument("--equal-sim-s", type=float, default=10.0)
    ap.add_argument("--equal-paper", action="store_true", help="lockstep = in-process on the paper mission")
    ap.add_argument("--equal-load", type=int, default=0, help="busy processes running meanwhile")
    ap.add_argument("--large-agents", type=int, nargs="*", default=[], help="lockstep on the grid: completes, "
                    "sim/wall, peak RSS per agent (e.g. 400 with --agents-per-process auto)")
    ap.add_argument("--large-sim-s", type=float, default=10.0)
    ap.add_argument("--paper-realtime", type=float, default=None, metavar="SPEED",
                    help="the paper at --clock realtime --speed SPEED: plain, with kill:agent:3@60, with flood@30")
    ap.add_argument("--paper-ros2", type=float, default=None, metavar="SPEED",
                    help="the paper in ROS 2 mode at --speed SPEED: plain, with kill:agent:3@60")
    ap.add_argument("--agents-per-process", nargs="*", default=["1"], metavar="K",
                    help="each row with K agents per process (agent hosts), side by side: 1 5 auto ...")
    ap.add_argument("--zenoh-mode", nargs="*", default=["auto"], choices=["auto", "client", "peer"],
                    help="each row with the processes as zenoh clients of the router and/or as peers, side by side "
                         "(auto: the launcher's rule; a checkout without the option: its own transport)")
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    if args.quick:
        args.grid_agents, args.grid_sim_s, args.realtime_agents, args.realtime_sim_s = [16], 5.0, [16], 8.0
    print("# bench_deploy: real processes (router, simworld, monitor, N agents) on 127.0.0.1")
    print(f"# {machine()}")
    print(f"# reproduce: {command_line()}")
    # (name, checkout, launcher options): this checkout at each K, then other checkouts at each K if they host
    # agents (else one process per agent)
    versions: list[tuple[str, Path | None, tuple[str, ...]]] = []
    for name, co in [("this", None), *((str(c), c) for c in args.checkout)]:
        for k in args.agents_per_process if co is None or hosts_agents(co) else ["1"]:
            for mode in args.zenoh_mode if co is None or has_option(co, "--zenoh-mode") else [None]:
                packed = () if k == "1" else ("--agents-per-process", k)
                linked = () if mode is None else ("--zenoh-mode", mode)
                label = [name, *([f"K={k}"] if packed else []), *([mode] if mode in ("client", "peer") else [])]
                versions.append((" ".join(label), co, packed + linked))
    with tempfile.TemporaryDirectory(prefix="bench_deploy_") as t:
        tmp = Path(t)
        if args.grid_agents:
            print(f"\n## lockstep on a sparse grid (about 8 neighbours each), {args.grid_sim_s:g} s simulated per run")
            print("CPU-ms per tick (user + sys, from each process's exit line); messages in and loop wake-ups per "
                  "agent per tick")
            print(f"{'version':>16s} {'N':>4s} {'sim/wall':>8s} {'agent':>7s} {'agents':>8s} {'world':>7s} "
                  f"{'monitor':>7s} {'router':>7s} {'msgs in':>7s} {'wakeups':>7s}")
        for n in args.grid_agents:
            for name, co, extra in versions:
                r = grid_row(tmp, n, args.grid_sim_s, co, extra)
                print(f"{name[-16:]:>16s} {n:4d} {r['sim_wall']:8.2f} {r['agent_ms']:7.2f} {r['agents_ms']:8.1f} "
                      f"{r['world_ms']:7.1f} {r['monitor_ms']:7.1f} {r['router_ms']:7.1f} {r['msgs_in']:7.1f} "
                      f"{r['wakeups']:7.1f}",
                      flush=True)
            for pat in args.floor:  # the same ticks as a row's long run minus its short one
                f = floor_run(n, pat, ticks=round(args.grid_sim_s * 2 / 3 / 0.05))
                print(f"{'floor-' + pat:>16s} {n:4d} {f['ticks_per_s'] * 0.05:8.2f} {f['agent_ms']:7.2f} "
                      f"{f['agents_ms']:8.1f} {f['world_ms']:7.1f} {'-':>7s} {f['router_ms']:7.1f} "
                      f"{f['msgs_in']:7.1f} {f['wakeups']:7.1f}", flush=True)
            print(f"# after N = {n}: {machine()}", flush=True)
        if args.paper:
            print("\n## the paper mission in lockstep (until it converges)")
            for i, (name, co, extra) in enumerate(versions):
                s = launch(tmp / f"paper-{i}", PAPER, free_port(), *extra, launcher=launcher_cmd(co))
                print(f"{name[-16:]:>16s} converged {s['converged']} at {s['convergence_time_s']} s in "
                      f"{s['wall_time_s']:.1f} s wall: sim/wall {s['duration_s'] / s['wall_time_s']:.2f}", flush=True)
        if args.large_agents:
            print(f"\n## large swarms in lockstep on the grid, {args.large_sim_s:g} s simulated")
            print(f"{'version':>16s} {'N':>4s} {'finished':>8s} {'sim/wall':>8s} {'collisions':>10s} {'lost':>5s} "
                  f"{'RSS MB':>8s} {'MB/agent':>8s} {'procs':>5s}")
            for n in args.large_agents:
                scen = tmp / f"large{n}.toml"
                scen.write_text(to_toml(grid_scenario(n, args.large_sim_s)))
                for i, (name, co, extra) in enumerate(versions):
                    out = tmp / f"large{n}-{i}"
                    s = launch(out, scen, free_port(), *extra, launcher=launcher_cmd(co))
                    rss, procs = peak_rss_mb(out)
                    print(f"{name[-16:]:>16s} {n:4d} {s['finished']!s:>8s} "
                          f"{s['duration_s'] / s['wall_time_s']:8.2f} {s['collisions']:10d} {len(s['agents_lost']):5d} "
                          f"{rss:8.0f} {rss / n:8.2f} {procs:5d}", flush=True)
        if args.paper_realtime is not None:
            print(f"\n## the paper at --clock realtime --speed {args.paper_realtime:g}")
            print(f"{'version':>16s} {'fault':>18s} {'converged':>9s} {'t (s)':>7s} {'missed':>7s} {'collisions':>10s} "
                  f"{'lost':>5s}")
            for fault in ("", "kill:agent:3@60", "flood@30"):
                for i, (name, co, extra) in enumerate(versions):
                    more = ("--fault", fault) if fault else ()
                    s = launch(tmp / f"paper-rt-{i}-{fault.replace(':', '_')}", PAPER, free_port(), "--clock",
                               "realtime", "--speed", f"{args.paper_realtime:g}", *more, *extra,
                               launcher=launcher_cmd(co))
                    print(f"{name[-16:]:>16s} {fault or '-':>18s} {s['converged']!s:>9s} "
                          f"{s['convergence_time_s'] or float('nan'):7.2f} {s.get('missed_deadline_ratio', 0):7.2%} "
                          f"{s['collisions']:10d} {len(s['agents_lost']):5d}", flush=True)
        if args.paper_ros2 is not None:
            print(f"\n## the paper in ROS 2 mode (--ros2) at --speed {args.paper_ros2:g}")
            print(f"{'version':>16s} {'fault':>16s} {'converged':>9s} {'t (s)':>7s} {'missed':>7s} {'p50 ms':>7s} "
                  f"{'p99 ms':>7s} {'collisions':>10s} {'lost':>5s} {'CPU s':>7s} {'procs':>5s}")
            for fault in ("", "kill:agent:3@60"):
                for i, (name, co, extra) in enumerate(versions):
                    out = tmp / f"paper-ros2-{i}-{fault.replace(':', '_')}"
                    more = ("--fault", fault) if fault else ()
                    try:
                        s = launch(out, PAPER, free_port(), "--ros2", "--speed", f"{args.paper_ros2:g}", *more,
                                   *extra, launcher=launcher_cmd(co))
                    except RuntimeError as exc:  # (a checkout that refuses --ros2 with agent hosts)
                        print(f"{name[-16:]:>16s} {fault or '-':>16s} {str(exc).splitlines()[-1][:80]}", flush=True)
                        continue
                    cpu, procs = cpu_s(out)
                    print(f"{name[-16:]:>16s} {fault or '-':>16s} {s['converged']!s:>9s} "
                          f"{s['convergence_time_s'] or float('nan'):7.2f} {s.get('missed_deadline_ratio', 0):7.2%} "
                          f"{s.get('latency_p50_ms', 0):7.2f} {s.get('latency_p99_ms', 0):7.2f} {s['collisions']:10d} "
                          f"{len(s['agents_lost']):5d} {cpu:7.1f} {procs:5d}", flush=True)
        if args.realtime_agents:
            print(f"\n## realtime at --speed 1 (20 Hz) on the grid, {args.realtime_sim_s:g} s per run")
            print(f"{'version':>16s} {'N':>4s} {'missed':>7s} {'ratio':>7s} {'lat p50 ms':>10s} {'lat p99 ms':>10s}")
            for i, (name, co, extra) in enumerate(versions):
                best = 0
                for n in args.realtime_agents:
                    scen = tmp / f"rt{n}.toml"
                    scen.write_text(to_toml(grid_scenario(n, args.realtime_sim_s)))
                    s = launch(tmp / f"rt{n}-{i}", scen, free_port(), "--clock", "realtime", "--speed", "1", *extra,
                               launcher=launcher_cmd(co))
                    ratio = s.get("missed_deadline_ratio", float("nan"))
                    print(f"{name[-16:]:>16s} {n:4d} {int(s.get('missed_deadlines', -1)):7d} {ratio:7.2%} "
                          f"{s.get('latency_p50_ms', 0):10.2f} {s.get('latency_p99_ms', 0):10.2f}", flush=True)
                    if not ratio < 0.01:
                        break
                    best = n
                print(f"{name[-16:]:>16s}: largest N at 20 Hz with < 1 % missed: {best or 'none of those tried'}")
        if args.equal_agents or args.equal_paper:
            print(f"\n## lockstep = in-process (reconswarm sim): the grid, {args.equal_sim_s:g} s simulated; the paper")
            for n in [*args.equal_agents, *([None] if args.equal_paper else [])]:
                for _name, co, extra in versions:
                    if co is None:
                        print(equal_run(tmp, n, args.equal_sim_s, args.equal_load, extra), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
