"""The launcher's processes run under SCHED_BATCH in lockstep and under the default policy in realtime
(reconswarm_bringup/fleet.py: Fleet.batch), the monitor at a lower priority (OBSERVER_NICE), and each agent
process on a CPU of its own, in turn (Fleet.cpus), threads included."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

from reconswarm_bringup.fleet import OBSERVER_NICE, Fleet, allowed_cpus
from tests.support import wait_until

pytestmark = pytest.mark.skipif(not hasattr(os, "SCHED_BATCH"), reason="SCHED_BATCH is Linux's")

# A child that starts a thread and prints the policy of both of its threads, as the kernel reports them.
CHILD = ("import os, threading, time; t = threading.Thread(target=time.sleep, args=(0.5,)); t.start(); "
         "print(os.sched_getscheduler(0), os.sched_getscheduler(t.native_id), flush=True); t.join()")


# The same child printing both threads' nice values.
NICE_CHILD = CHILD.replace("os.sched_getscheduler(0), os.sched_getscheduler(t.native_id)",
                           "os.getpriority(os.PRIO_PROCESS, 0), os.getpriority(os.PRIO_PROCESS, t.native_id)")


# The same child printing both threads' CPUs (the lowest and the highest each may run on).
CPU_CHILD = CHILD.replace("os.sched_getscheduler(0), os.sched_getscheduler(t.native_id)",
                          "*(f(os.sched_getaffinity(x)) for x in (0, t.native_id) for f in (min, max))")


def run_child(fleet: Fleet, role: str, ident: str = "-", child: str = CHILD) -> list[int]:
    # Fleet starts `python -m reconswarm_bringup.cli ARGS`; the prefix turns that into `python -c CHILD`.
    proc = fleet.start(role, ident, [], prefix=[sys.executable, "-c", child, "--"])
    assert proc.popen.wait(timeout=60) == 0
    return [int(x) for x in wait_until(lambda: proc.log_path.read_text().split(), 10, f"{proc.log_path} written")]


def policies(tmp_path: Path, batch: bool, role: str = "probe", child: str = CHILD) -> list[int]:
    return run_child(Fleet(tmp_path, dict(os.environ), batch=batch), role, child=child)


def test_lockstep_processes_run_under_sched_batch_and_realtime_ones_do_not(tmp_path: Path) -> None:
    assert policies(tmp_path / "lockstep", True) == [os.SCHED_BATCH, os.SCHED_BATCH]
    assert policies(tmp_path / "realtime", False) == [os.SCHED_OTHER, os.SCHED_OTHER]


def test_the_monitor_runs_at_a_lower_priority_and_the_control_loop_does_not(tmp_path: Path) -> None:
    ours = os.getpriority(os.PRIO_PROCESS, 0)
    assert OBSERVER_NICE > 0
    for clock, batch in (("lockstep", True), ("realtime", False)):
        want = min(19, ours + OBSERVER_NICE)
        assert policies(tmp_path / clock / "monitor", batch, "monitor", NICE_CHILD) == [want, want]
        for role in ("simworld", "agent", "router"):
            assert policies(tmp_path / clock / role, batch, role, NICE_CHILD) == [ours, ours]


@pytest.mark.skipif(len(allowed_cpus()) < 2, reason="pinning spreads agent processes over at least 2 CPUs")
def test_each_agent_process_runs_on_a_cpu_of_its_own_in_turn_and_the_other_roles_are_free(tmp_path: Path) -> None:
    cpus = allowed_cpus()
    free = [min(cpus), max(cpus)] * 2  # (both threads: any CPU this test may use)
    fleet = Fleet(tmp_path / "pinned", dict(os.environ), cpus=cpus)
    for i, ident in enumerate(["1-5", "6-10", "11"]):  # (a third process on 2 CPUs: the first CPU again)
        want = cpus[i % len(cpus)]
        assert run_child(fleet, "agent", ident, CPU_CHILD) == [want] * 4
    (tmp_path / "pinned" / "logs" / "agent-1-5.log").unlink()
    assert run_child(fleet, "agent", "1-5", CPU_CHILD) == [cpus[0]] * 4  # a restart keeps its CPU (not the next)
    for role in ("simworld", "monitor", "router"):
        assert run_child(fleet, role, child=CPU_CHILD) == free
    assert run_child(Fleet(tmp_path / "free", dict(os.environ)), "agent", "1", CPU_CHILD) == free
