"""The run's processes: started with subprocess (no fork of a zenoh-holding process), logged, tracked, stopped."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
# The monitor observes: it is on no tick's path (the world waits for agents, never for it) and keeps up in the
# cores' idle moments, so it runs at a lower priority and leaves the CPU to the control loop whenever both want
# it (the paper in lockstep: about 7 % more ticks a second). On a saturated machine it still gets a share (nice
# 10 weighs about a tenth of a default process) and catches up.
OBSERVERS = frozenset({"monitor"})  # roles on no tick's path
OBSERVER_NICE = 10  # added to their nice value
# Agent hosts run on the CPUs in turn, one CPU each while there are as many CPUs as hosts (one process per agent
# stays free: reconswarm_bringup/packing.py): left free, the scheduler may put both of the paper's hosts on one
# CPU for a while as the world and the monitor wake on the other, and every lockstep tick waits for the slower.
# Measured on 2 CPUs beside the processes free (docs/benchmarks.md): the paper in lockstep 8-21 % faster at K = 5
# and 10; realtime x10 at K = 5 missed 4-7 % of its deadlines, not 11-13 %. The world, the monitor and the
# routers stay free.
PINNED = frozenset({"agent"})  # roles given a CPU each (`--no-pin-cpus`: none)


@dataclass
class Proc:
    role: str
    id: str
    args: list[str]
    popen: subprocess.Popen[bytes]
    log_path: Path
    prefix: list[str] = field(default_factory=list)  # e.g. `ip netns exec NS` for host B
    expected_exit: bool = False  # stopped on purpose (a fault or the end of the run)
    members: tuple[str, ...] = ()  # an agent host: the agents it runs (its id names them all, e.g. 1-5)

    @property
    def name(self) -> str:
        """As the launcher's lines name it: `router`, `monitor`, `agent 1-5`, `router B` (its id, when it has one)."""
        return self.role if self.id == "-" else f"{self.role} {self.id}"

    @property
    def idents(self) -> tuple[str, ...]:
        """Whom this process stands for: its id, or each agent of a host."""
        return self.members or (self.id,)


@dataclass
class Fleet:
    """The run's processes: started with subprocess (no fork of a zenoh-holding process), logged, tracked."""

    out: Path
    env: dict[str, str]
    procs: list[Proc] = field(default_factory=list)
    zopt: Any = None  # (role, id) -> (command prefix, zenoh args), set by run()
    router_env: dict[str, str] | None = None  # the routers' environment, when it differs from env
    # Lockstep is a throughput job: every process runs under SCHED_BATCH, which the kernel never lets preempt
    # a running task when it wakes (a process woken by a message waits for the CPU's current holder to
    # block, as it soon does, instead of evicting it mid-tick). Measured on the paper mission, side by side
    # with the default policy: 25-40 % less kernel CPU in the agents, sim/wall median 5.4 against 4.8.
    # Realtime keeps the default policy: there a woken process should run at once.
    batch: bool = False
    cpus: tuple[int, ...] = ()  # the CPUs the PINNED roles' processes take, one each in turn (none: not pinned)
    pinned: dict[str, int] = field(default_factory=dict)  # process id (`1-5`) -> its CPU (a restart keeps it)

    def start(self, role: str, ident: str, args: list[str], prefix: list[str] | None = None,
              members: tuple[str, ...] = ()) -> Proc:
        """Start a process; processes.tsv gets a line per agent it runs (an agent host's share its pid). Each is
        in a process group of its own: a Ctrl-C at the terminal reaches the launcher alone, which stops them in
        order (the world first, the monitor closing the record) at any moment, start-up included."""
        logs = self.out / "logs"
        logs.mkdir(parents=True, exist_ok=True)
        name = role if ident == "-" else f"{role}-{ident}"
        log_path = logs / f"{name}.log"
        fh = log_path.open("ab")
        popen = subprocess.Popen([*(prefix or []), sys.executable, "-m", "reconswarm_bringup.cli", *args], stdout=fh,
                                 stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                 env=self.router_env if role == "router" and self.router_env else self.env,
                                 cwd=str(ROOT), process_group=0)
        fh.close()
        if self.batch:  # Popen returns once the child exec'd, before its interpreter starts a thread (they inherit it)
            batch_policy(popen.pid)
        if role in OBSERVERS:
            lower_priority(popen.pid, OBSERVER_NICE)
        if role in PINNED and len(self.cpus) > 1:
            pin(popen.pid, self.pinned.setdefault(ident, self.cpus[len(self.pinned) % len(self.cpus)]))
        proc = Proc(role, ident, args, popen, log_path, list(prefix or []), members=tuple(members))
        self.procs.append(proc)
        with (self.out / "processes.tsv").open("a") as tsv:
            tsv.writelines(f"{role}\t{who}\t{popen.pid}\n" for who in proc.idents)
        return proc

    def find(self, role: str, ident: str = "-") -> Proc | None:
        """The newest process of that role standing for ident (an agent: its own process or its host)."""
        live = [p for p in self.procs if p.role == role and ident in p.idents]
        return live[-1] if live else None

    def restart(self, proc: Proc) -> Proc:
        return self.start(proc.role, proc.id, proc.args, proc.prefix, proc.members)

    def signal(self, proc: Proc, sig: int) -> None:
        if proc.popen.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(proc.popen.pid, sig)

    def stop_all(self, grace_s: float = 3.0) -> None:
        """SIGCONT (frozen ones), SIGTERM, then SIGKILL what is still there; reap everything."""
        order = ["simworld", "agent", "monitor", "flood", "router"]
        for role in order:
            for p in self.procs:
                if p.role == role and p.popen.poll() is None:
                    p.expected_exit = True
                    self.signal(p, signal.SIGCONT)
                    self.signal(p, signal.SIGTERM)
            deadline = time.monotonic() + grace_s
            for p in self.procs:
                if p.role == role:
                    try:
                        p.popen.wait(timeout=max(0.0, deadline - time.monotonic()))
                    except subprocess.TimeoutExpired:
                        self.signal(p, signal.SIGKILL)
                        p.popen.wait()


def lower_priority(pid: int, nice: int) -> None:
    """Raise process `pid`'s nice value by `nice` (a lower priority; any user may); a refusal leaves it as it is."""
    with contextlib.suppress(OSError):
        os.setpriority(os.PRIO_PROCESS, pid, os.getpriority(os.PRIO_PROCESS, pid) + nice)


def allowed_cpus() -> tuple[int, ...]:
    """The CPUs this process may run on, in order (none where the platform cannot tell or pin)."""
    try:
        return tuple(sorted(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return ()


def pin(pid: int, cpu: int) -> None:
    """Run process `pid` (and the threads it starts) on CPU `cpu` alone; a kernel that refuses it leaves it free."""
    with contextlib.suppress(OSError, AttributeError):
        os.sched_setaffinity(pid, {cpu})


def batch_policy(pid: int) -> None:
    """Run process `pid` under SCHED_BATCH (see Fleet.batch); a kernel that refuses it leaves the default."""
    with contextlib.suppress(OSError, AttributeError):
        os.sched_setscheduler(pid, os.SCHED_BATCH, os.sched_param(0))
