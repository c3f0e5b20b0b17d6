#!/usr/bin/env python3
"""Mutation testing of the core modules with mutmut 3 (`pip install -e '.[mutation]'`): each module is mutated
alone, in a copy of the work tree (the tree itself is never touched), against the unit tests that cover it;
prints per module how many mutants the tests killed and how many survived, and the survivors' names (with
--diff, each survivor's change). Slow (minutes to tens of minutes per module on two cores): not part of CI.

    python bench/mutation.py                                   # every core module
    python bench/mutation.py reconswarm/plant/unicycle.py --jobs 2 --diff
    python bench/mutation.py --list                            # the modules and their tests
    python bench/mutation.py simworld/world.py --json before.json          # then, with new tests:
    python bench/mutation.py simworld/world.py --rerun before.json         # only before.json's survivors

A survivor is a change of the code that none of the module's tests notices: either a test to write, or an
equivalent change (the same behaviour, e.g. `<` for `<=` where equality cannot happen) to accept and record.
"""

from __future__ import annotations

import _venv  # noqa: F401  (first: the project's .venv, re-run there if this Python lacks it)

# isort: split
import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("reconswarm", "agent", "simworld", "monitor", "reconswarm_bringup")

# The core modules and the unit tests that hold them (unit tests only: no processes, seconds each).
CORE: dict[str, tuple[str, ...]] = {
    "reconswarm/paper/planner.py": ("test_planner.py", "test_admission.py", "test_engine.py", "test_planner_cases.py"),
    "reconswarm/plant/unicycle.py": ("test_unicycle.py", "test_unicycle_vw.py", "test_unicycle_limits.py"),
    "reconswarm/paper/topology.py": ("test_topology_metrics.py", "test_summary_counts.py", "test_topology_cases.py"),
    "reconswarm/net/wire/wire.py": ("test_wire.py", "test_wire_points.py", "test_wire_fields.py", "test_wire_cases.py"),
    "reconswarm/net/trust/admission.py": ("test_admission.py", "test_membership_rules.py", "test_admission_cases.py"),
    "reconswarm/record/summary.py": ("test_summary_counts.py", "test_monitor_node.py", "test_run_store.py",
                                     "test_summary_fields.py"),
    "reconswarm/record/safety.py": ("test_safety_episodes.py", "test_summary_counts.py", "test_topology_metrics.py"),
    "agent/node.py": ("test_agent_node.py", "test_agent_node_waits.py", "test_agent_node_cases.py",
                      "test_agent_node_outputs.py"),
    "simworld/world.py": ("test_world_node.py", "test_world_uncommanded.py", "test_world_node_cases.py"),
    "simworld/robots.py": ("test_world_node.py", "test_ros2_robots_live.py", "test_robots_cases.py",
                           "test_robots_bodies.py"),
    "monitor/node.py": ("test_monitor_node.py", "test_membership_rules.py", "test_world_uncommanded.py",
                        "test_monitor_node_cases.py"),
    "monitor/presence.py": ("test_monitor_node.py", "test_membership_rules.py", "test_presence_cases.py"),
    "reconswarm/paper/blocked.py": ("test_blocked.py", "test_blocked_cases.py", "test_agent_node.py",
                                    "test_agent_node_cases.py"),
    "reconswarm/net/trust/membership.py": ("test_membership_rules.py", "test_membership_cases.py", "test_world_node.py",
                                     "test_world_node_cases.py", "test_monitor_node.py", "test_presence_cases.py",
                                     "test_router_link.py"),
    "reconswarm/paper/deadlock.py": ("test_deadlock_leader.py", "test_deadlock_cases.py", "test_law_batched.py"),
    "reconswarm/net/trust/gate.py": ("test_admission.py", "test_gate_cases.py", "test_agent_host_routing.py",
                               "test_agent_node.py", "test_ros2_admission.py", "test_world_node.py"),
    "agent/heard.py": ("test_heard.py", "test_heard_cases.py", "test_agent_node.py", "test_agent_node_cases.py",
                       "test_agent_node_waits.py", "test_agent_node_outputs.py"),
    "agent/neighbours.py": ("test_neighbours.py", "test_neighbours_cases.py", "test_agent_node.py",
                            "test_agent_node_cases.py", "test_agent_node_outputs.py", "test_agent_host_routing.py"),
    "agent/brain.py": ("test_agent_brain_vs_engine.py", "test_agent_node.py", "test_agent_node_law.py",
                       "test_agent_node_cases.py", "test_agent_node_outputs.py", "test_blocked.py",
                       "test_law_batched.py", "test_agent_brain_cases.py"),
    "reconswarm/paper/knowledge.py": ("test_sensing_knowledge.py", "test_planner.py", "test_agent_brain_vs_engine.py",
                                      "test_knowledge_cases.py"),
    "reconswarm/net/wire/cells.py": ("test_cells.py", "test_cells_cases.py", "test_neighbours.py",
                                     "test_robots_cases.py"),
    "agent/host.py": ("test_agent_host_routing.py", "test_agent_host_cases.py", "test_agent_host_sessions.py",
                      "test_inbox_urgent.py", "test_runtime.py", "test_law_batched.py"),
    "agent/ros2_io.py": ("test_ros2_plan_age.py", "test_agent_host_sessions.py", "test_ros2_admission.py"),
    "simworld/ros2_io.py": ("test_ros2_plan_age.py", "test_ros2_robots_live.py", "test_ros2.py", "test_robots_reach.py",
                            "test_ros2_admission.py"),
}

# mutmut's exit codes (mutmut.stats.status_by_exit_code): 1 and 3 killed, 0 survived, the rest neither.
KILLED, SURVIVED = {1, 3}, {0}


def copy_tree(dest: Path) -> None:
    """The work tree as it stands (tracked and new files, not ignored ones) into dest."""
    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=ROOT, check=True,
                           capture_output=True).stdout.decode().split("\0")
    for name in filter(None, files):
        src = ROOT / name
        if src.is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name)


def configure(tree: Path, module: str, tests: tuple[str, ...]) -> None:
    """mutmut's settings in the copy's pyproject.toml: mutate `module` only, run `tests`."""
    cfg = "\n".join([
        "", "[tool.mutmut]",
        f"source_paths = {json.dumps(list(PACKAGES))}",
        f"only_mutate = {json.dumps([module])}",
        'also_copy = ["deploy"]',  # the scenarios the tests load
        f"pytest_add_cli_args_test_selection = {json.dumps([f'tests/unit/{t}' for t in tests])}",
        'pytest_add_cli_args = ["-p", "no:cacheprovider", "-q", "-x"]',
        "use_git_change_detection = false",
        # Mutants are forked from a server that has only collected the tests: the tests that open a zenoh
        # session hang in a child forked from a process whose zenoh runtime already runs (mutmut's default).
        'process_isolation = "forkserver"',
        'forkserver_warmup = "collect"',
        "",
    ])
    with (tree / "pyproject.toml").open("a") as fh:
        fh.write(cfg)
    # Hypothesis in the copy: no shrinking (a failing example kills the mutant as it is; shrinking it took
    # so long that mutmut timed the mutant out) and few examples unless a test asks for more.
    with (tree / "tests" / "conftest.py").open("a") as fh:
        fh.write("\n\nfrom hypothesis import Phase as _Phase\nfrom hypothesis import settings as _settings\n\n"
                 "_settings.register_profile('mutation', max_examples=25, deadline=None, database=None,\n"
                 "                           phases=[_Phase.explicit, _Phase.reuse, _Phase.generate])\n"
                 "_settings.load_profile('mutation')\n")


def outcomes(tree: Path, module: str) -> dict[str, int | None]:
    """mutant name -> exit code, from mutmut's record of the module."""
    meta = tree / "mutants" / (module + ".meta")
    return dict(json.loads(meta.read_text())["exit_code_by_key"]) if meta.exists() else {}


def run_module(module: str, tests: tuple[str, ...], jobs: int, diff: bool, keep: bool,
               only: list[str] | None = None) -> dict[str, object]:
    tree = Path(tempfile.mkdtemp(prefix="mutation-"))
    try:
        copy_tree(tree)
        configure(tree, module, tests)
        env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1"}
        t0 = time.monotonic()
        p = subprocess.run([sys.executable, "-m", "mutmut", "run", "--max-children", str(jobs), *(only or [])],
                           cwd=tree, env=env, capture_output=True, text=True)
        took = time.monotonic() - t0
        codes = outcomes(tree, module)
        if only is not None:  # (the others were not run)
            codes = {k: c for k, c in codes.items() if k in set(only)}
        if not codes or all(c is None for c in codes.values()):  # (mutmut's clean run of the tests failed)
            tail = (p.stdout + p.stderr)[-3000:]
            raise SystemExit(f"mutation: mutmut checked no mutant of {module} (exit {p.returncode}):\n{tail}")
        killed = sorted(k for k, c in codes.items() if c in KILLED)
        survived = sorted(k for k, c in codes.items() if c in SURVIVED)
        other = Counter(str(c) for k, c in codes.items() if c not in KILLED | SURVIVED)
        diffs = {}
        if diff:
            for name in survived:
                d = subprocess.run([sys.executable, "-m", "mutmut", "show", name], cwd=tree, capture_output=True,
                                   text=True)
                diffs[name] = d.stdout
        return {"module": module, "tests": list(tests), "mutants": len(codes), "killed": len(killed),
                "survived": survived, "other": dict(other), "seconds": round(took, 1), "diffs": diffs,
                "tree": str(tree) if keep else None}
    finally:
        if not keep:
            shutil.rmtree(tree, ignore_errors=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("modules", nargs="*", help="paths of core modules (default: all of them)")
    ap.add_argument("--jobs", type=int, default=2, help="mutants tested at once (default 2)")
    ap.add_argument("--diff", action="store_true", help="print each survivor's change")
    ap.add_argument("--json", type=Path, help="also write the figures to this file")
    ap.add_argument("--keep", action="store_true", help="keep the mutated copies (mutmut browse there)")
    ap.add_argument("--list", action="store_true", help="list the core modules and their tests")
    ap.add_argument("--rerun", type=Path, metavar="JSON",
                    help="test only the survivors of an earlier run (its --json file), e.g. after writing tests")
    a = ap.parse_args(argv)
    if a.list:
        for m, t in CORE.items():
            print(f"{m}: {', '.join(t)}")
        return 0
    unknown = [m for m in a.modules if m not in CORE]
    if unknown:
        print(f"mutation: error: not a core module: {', '.join(unknown)} (see --list)", file=sys.stderr)
        return 2
    if a.jobs < 1:
        print("mutation: error: --jobs: must be at least 1", file=sys.stderr)
        return 2
    try:
        import mutmut  # noqa: F401
    except ImportError:
        print("mutation: error: mutmut is not installed (pip install -e '.[mutation]')", file=sys.stderr)
        return 2
    earlier: dict[str, list[str]] = {}
    if a.rerun:
        try:
            earlier = {r["module"]: list(r["survived"]) for r in json.loads(a.rerun.read_text())}
        except (OSError, ValueError, KeyError, TypeError) as e:
            print(f"mutation: error: --rerun {a.rerun}: not a --json file of this script ({e})", file=sys.stderr)
            return 2
    rows = []
    for m in a.modules or list(CORE):
        if a.rerun and m not in earlier:
            print(f"mutation: error: --rerun {a.rerun}: no run of {m} in it", file=sys.stderr)
            return 2
        r = run_module(m, CORE[m], a.jobs, a.diff, a.keep, earlier.get(m) if a.rerun else None)
        rows.append(r)
        rerun = " (survivors rerun)" if a.rerun else ""
        print(f"{m}: {r['mutants']} mutants{rerun}, {r['killed']} killed, {len(r['survived'])} survived"  # type: ignore[arg-type]
              f"{', other ' + json.dumps(r['other']) if r['other'] else ''} ({r['seconds']} s)", flush=True)
        for name in r["survived"]:  # type: ignore[attr-defined]
            print(f"  survived: {name}")
            if a.diff:
                print("    " + r["diffs"][name].replace("\n", "\n    "))  # type: ignore[index]
    print(f"{'module':<34} {'mutants':>7} {'killed':>7} {'survived':>8}")
    for r in rows:
        print(f"{r['module']:<34} {r['mutants']:>7} {r['killed']:>7} {len(r['survived']):>8}")  # type: ignore[arg-type]
    if a.json:
        a.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
