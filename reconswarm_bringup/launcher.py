"""The main job behind `deploy/run_local.sh`: one run of the mission as separate processes.

Starts a zenoh router (unless --router names one), the monitor, one process per agent and simworld,
each with its log in OUTDIR/logs/ and a line in OUTDIR/processes.tsv (role, id, pid) as it starts;
follows the clock to show progress and to fire faults at simulated times; restarts the monitor or a
router (on its endpoint) if it dies; when the world ends the mission it lets everyone finish, stops what
is left, prints the summary and returns the documented exit code. SIGINT / SIGTERM stop everything; every
child is also bound to this process (PR_SET_PDEATHSIG) so none outlives it.
"""

from __future__ import annotations

import contextlib
import logging
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from reconswarm.cli import outputs
from reconswarm.errors import BadInput
from reconswarm.net.runtime.session import DEFAULT_ROUTER
from reconswarm.net.timing import TIMING
from reconswarm.planners import registry
from reconswarm.scenario.generate import generate
from reconswarm.scenario.model import Scenario, load, parse, to_toml, warnings
from reconswarm_bringup import chaos, netns, outcome, outdir, packing, runid, validate
from reconswarm_bringup.clockwatch import ClockWatch
from reconswarm_bringup.config import LaunchConfig
from reconswarm_bringup.fleet import ROOT, Fleet, Proc, allowed_cpus
from reconswarm_bringup.network import Net, check_live_port, plan_network
from reconswarm_bringup.restarts import MONITOR_DELAYS_S, ROUTER_DELAYS_S, Restarts

log = logging.getLogger("reconswarm.launch")
PAPER = ROOT / "deploy" / "scenarios" / "paper.toml"
ZENOH_RUNTIME = "(" + ", ".join(f"{pool}: (worker_threads: 1)" for pool in ("app", "acc", "tx", "rx", "net")) + ")"


def prepare_scenario(cfg: LaunchConfig) -> tuple[Scenario, list[str]]:
    """The scenario of the run, checked against the machine and the faults (nothing written yet)."""
    if cfg.scenario is not None and cfg.agents is not None:
        raise BadInput("-n/--agents and -s/--scenario: give one (-n generates a scenario)")
    if cfg.agents is not None:
        option = f"-n {cfg.agents}"
        validate.machine_holds(option, cfg.agents, validate.available_memory_mb(), routers=cfg.hosts,
                               per_process=packing.per_process(cfg.agents_per_process, cfg.agents))
        # Through the loader's checks (what the wire can carry, ...), as every process will read it.
        s = parse(to_toml(generate(cfg.agents, max(1, min(10, cfg.agents // 5 + 2)), 0)), f"{option} (generated)")
    else:
        s = load(cfg.scenario or PAPER)
        per = packing.per_process(cfg.agents_per_process, len(s.agents))
        validate.machine_holds(f"-s {cfg.scenario or PAPER}", len(s.agents), validate.available_memory_mb(),
                               routers=cfg.hosts, per_process=per)
    warns = warnings(s)
    for w in warns:
        log.warning("warning: %s", w)
    validate.fault_targets(cfg.faults, {a.id for a in s.agents})
    s = s if cfg.planner is None else s.with_planner(cfg.planner)
    registry.require(s)  # (an optional dependency the planner needs: refused here, not in every agent)
    return s, warns


def run(cfg: LaunchConfig) -> int:
    outputs.creatable_dir("-o", cfg.out)  # (nothing is created before every check has passed)
    if cfg.clock not in ("lockstep", "realtime"):
        raise BadInput(f"--clock: expected lockstep or realtime, got {cfg.clock!r}")
    if any(f.action == "partition" for f in cfg.faults) and cfg.hosts != 2:
        raise BadInput("--fault partition@...: needs --hosts 2 (two hosts to cut apart)")
    check_live_port(cfg)
    s, warns = prepare_scenario(cfg)  # refused before anything of a previous run in OUTDIR is touched
    made = not cfg.out.exists()
    had_secrets = (cfg.out / "secrets").exists()
    outputs.writable_dir("-o", cfg.out)
    # OUTDIR is ours for the run: not while another launch or a `reconswarm sim` writes there (its record would go).
    claim = outdir.RecordClaim(cfg.out, replaces=None, what="a launch (run_local.sh)")
    try:
        claim.acquire()
    except BaseException:
        _undo(cfg.out, made, had_secrets)
        raise
    scen_path = cfg.out / "scenario.toml"  # every process reads the same file
    router_env = dict(os.environ, RECONSWARM_DIE_WITH_PARENT=str(os.getpid()), PYTHONUNBUFFERED="1")
    env = dict(router_env)
    # One worker thread per zenoh runtime pool in the clients: a process here handles a few hundred messages
    # a second, and fewer threads mean fewer hand-offs (measured ~3 % less CPU on the paper mission). Not in
    # routers: a router whose one tx thread waits on a dead link (a partition, until the lease runs out and
    # after) stops forwarding for everyone else too; measured: the whole of host A stalled for the 10 s cut.
    env.setdefault("ZENOH_RUNTIME", ZENOH_RUNTIME)
    fleet = Fleet(cfg.out, env, router_env=router_env, batch=cfg.clock == "lockstep",
                  cpus=allowed_cpus() if cfg.pin_cpus else ())
    stop_sig: list[int] = []

    def on_signal(signum: int, _frame: Any) -> None:
        stop_sig.append(signum)

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, on_signal)

    # One launch, one run: the run id names every key of this run (swarm/<run>/...), so two launches never
    # hear each other; it is in OUTDIR/run_id before any process starts.
    run_id = runid.new_run_id(s.meta.name)
    lock = runid.EndpointLock(cfg.router or DEFAULT_ROUTER)
    net: Net | None = None
    watch: ClockWatch | None = None
    code = 3
    going = False  # the run goes ahead: OUTDIR's earlier run gives way to this one's files
    try:
        net = plan_network(cfg, s, run_id, lock)
        _replace_earlier(cfg.out, made)
        going = True
        scen_path.write_text(to_toml(s))
        runid.write_run_id(cfg.out, run_id)
        if cfg.latest:
            outdir.link_latest(cfg.out)
        log.info("run %s: record and logs in %s%s", run_id, cfg.out,
                 f" ({cfg.out.parent / outdir.LATEST} links to it)" if cfg.latest else "")
        fleet.zopt = net.zopt
        run_arg = ["--run", run_id]
        routers = [fleet.start("router", ident, args, prefix) for ident, args, prefix in net.routers]
        net.wait_router(lambda: all(r.popen.poll() is None for r in routers))
        if cfg.ros_domain_id is not None:
            secrets = (cfg.out / "secrets").resolve() if cfg.secure else None
            outcome.ros2_notice(net.watch.connect[0], cfg.ros_domain_id, secrets)
        prefix, zargs = net.zopt("monitor")
        live = [] if cfg.foxglove_port is None else ["--foxglove", str(cfg.foxglove_port)]
        mon = fleet.start("monitor", "-", ["monitor", "record", "--scenario", str(scen_path), "--db",
                                           str(cfg.out / "run.db"), "--no-live", *live, *run_arg, *zargs], prefix)
        ros = [] if cfg.ros_domain_id is None else ["--ros2", "--ros-domain-id", str(cfg.ros_domain_id)]
        packing.start_agents(fleet, s, cfg.agents_per_process, net.zopt, ["--scenario", str(scen_path), *ros, *run_arg])
        prefix, zargs = net.zopt("simworld")
        world = fleet.start("simworld", "-", ["simworld", "--scenario", str(scen_path), "--clock", cfg.clock,
                                              "--speed", str(cfg.speed), "--start-timeout", str(cfg.start_timeout_s),
                                              *ros, *run_arg, *zargs], prefix)
        watch = ClockWatch(run_id, net.watch, s)
        code = _supervise(cfg, s, fleet, world, mon, watch, stop_sig, warns)
    finally:
        if watch is not None:
            watch.close()
        fleet.stop_all()
        if net is not None and net.hosts is not None:
            net.hosts.delete()
            netns.ACTIVE.clear()
        lock.release()
        claim.release()
        if not going:
            _undo(cfg.out, made, had_secrets)
    if stop_sig:
        log.warning("stopped by signal %d", stop_sig[0])
        return 128 + stop_sig[0]
    return code


def _replace_earlier(out: Path, made: bool) -> None:
    """The files of the run OUTDIR held before go; a record among them is named as it goes (runs without -o
    keep theirs: each has its own directory)."""
    if not made and (out / "run.db").exists():
        before = "?"
        with contextlib.suppress(OSError):
            before = runid.read_run_id(out)
        log.warning("-o %s: replacing the record of run %s there (without -o, each run has its own directory "
                    "under runs/)", out, before)
    for stale in ("processes.tsv", "faults.tsv", "run.db", "run.db-wal", "run.db-shm", runid.RUN_ID_FILE):
        (out / stale).unlink(missing_ok=True)


def _undo(out: Path, made: bool, had_secrets: bool) -> None:
    """A launch refused before its run started leaves nothing behind: the directory it made, or what it wrote
    into one that was there."""
    if made:
        shutil.rmtree(out, ignore_errors=True)
    elif not had_secrets:
        shutil.rmtree(out / "secrets", ignore_errors=True)


def _supervise(cfg: LaunchConfig, s: Scenario, fleet: Fleet, world: Proc, mon: Proc, watch: ClockWatch,
               stop_sig: list[int], warns: list[str]) -> int:
    pending = sorted(cfg.faults, key=lambda f: f.at_s)
    timers: list[tuple[float, Any]] = []  # (wall time, action)
    wall0 = time.monotonic()
    bar = _Progress(cfg.progress and sys.stderr.isatty() and not cfg.as_json, s.meta.duration_s,
                    log_lines=cfg.progress)  # --no-progress: no bar, and no `t = ...` lines either
    crashed: list[str] = []
    fatal: str | None = None  # the run cannot go on: stop everything, print the summary, exit 3
    halt: str | None = None  # the launcher ends the run early: "stopped" (a signal) or "timeout"
    live = outcome.LiveViewNotice(cfg.foxglove_port)
    monitor_restarts = Restarts(MONITOR_DELAYS_S)
    router_restarts = Restarts(ROUTER_DELAYS_S)
    try:
        while not stop_sig and fatal is None:
            watch.poll()
            now = time.monotonic()
            while pending and watch.k >= 0 and watch.t >= pending[0].at_s and watch.end is None:
                f = pending.pop(0)
                log.warning("fault: %s", f.describe())
                with (cfg.out / "faults.tsv").open("a") as tsv:
                    tsv.write(f"{time.time():.6f}\t{watch.t:.3f}\t{f.describe()}\n")
                timers += chaos.inject(f, fleet, watch.keys.run, cfg.out / "scenario.toml")
            for item in [x for x in timers if x[0] <= now]:
                timers.remove(item)
                item[1]()
            for p in fleet.procs:
                rc = p.popen.poll()
                if rc is not None and not p.expected_exit and p.role in ("agent", "router", "monitor"):
                    p.expected_exit = True
                    if p.role == "monitor" and rc == 0:
                        continue  # it saw the end of the mission and closed the record
                    if p.role == "monitor" and world.popen.poll() is None:
                        why = outcome.last_line(p.log_path)
                        if "disk full" in why or rc == 2:  # (2: bad input, which a restart does not mend)
                            fatal = why
                        elif (delay := monitor_restarts.after_death()) is None:
                            fatal = f"the monitor died {monitor_restarts.done + 1} times (last: exit {rc}: {why})"
                        else:
                            log.warning("monitor died (exit %s: %s): restarting it in %.1f s (%d of %d)", rc, why,
                                        delay, monitor_restarts.done, monitor_restarts.limit)
                            timers.append((now + delay, lambda p=p: fleet.restart(p)))
                    elif p.role == "router" and world.popen.poll() is None:
                        # The same endpoint again: every client reconnects by itself (the world and the monitor
                        # judge nobody while their own link is gone: reconswarm/net/runtime/uplink.py).
                        if (delay := router_restarts.after_death()) is None:
                            fatal = f"the router died {router_restarts.done + 1} times (last: exit {rc}: " \
                                    f"{outcome.last_line(p.log_path)})"
                        else:
                            log.warning("%s died (exit %s) at t = %.2f s: restarting it on the same endpoint "
                                        "in %.1f s (%d of %d)", p.name, rc, watch.t, delay, router_restarts.done,
                                        router_restarts.limit)
                            timers.append((now + delay, lambda p=p: fleet.restart(p)))
                    elif p.role == "agent" and rc == 2 and watch.k < 0:
                        # Refused its input before the mission began: it will not come, and the world would wait
                        # its whole start timeout for it.
                        fatal = f"{p.name} could not start (exit 2: {outcome.last_line(p.log_path)})"
                    elif rc != 0 and watch.end is None:
                        crashed.append(f"{p.name} exited {rc}")
                        log.warning("%s exited with %s", p.name, rc)
            bar.update(watch.t, watch.alive, len(s.agents))
            live.poll()
            if world.popen.poll() is not None:
                break
            if cfg.timeout_s is not None and now - wall0 > cfg.timeout_s:
                log.error("timeout after %.0f s of wall time at t = %.2f s: stopping the run", cfg.timeout_s, watch.t)
                halt = "timeout"
                break
            time.sleep(0.05)
        rc = world.popen.returncode
        if stop_sig or halt is not None:
            halt = halt or "stopped"
            _wind_down(fleet, world)
        elif fatal is None and rc is not None and rc != 0:
            why = outcome.last_line(world.log_path)
            how = f"killed by {signal.Signals(-rc).name}" if rc < 0 else f"exit {rc}: {why}"
            fatal = f"simworld died ({how}) at t = {watch.t:.2f} s: the mission ended without its world"
            log.error("%s; stopping the run", fatal)
            time.sleep(TIMING.world_stall_s + 0.5)  # the monitor notices the stall before the agents leave
        if fatal is not None:
            fleet.stop_all()  # the agents first, then the monitor (which closes the record)
        else:
            last = fleet.find("monitor") or mon
            try:  # the monitor writes the last ticks and closes the record
                last.popen.wait(timeout=15)
            except subprocess.TimeoutExpired:
                log.warning("monitor did not finish in time")
            deadline = time.monotonic() + 5
            for p in fleet.procs:
                if p.role == "agent" and p.popen.poll() is None:
                    with contextlib.suppress(subprocess.TimeoutExpired):
                        p.popen.wait(timeout=max(0.1, deadline - time.monotonic()))
    finally:
        bar.close()
    return outcome.report(cfg, crashed, fatal, halt, warns)


def _wind_down(fleet: Fleet, world: Proc, monitor_wait_s: float = 8.0) -> None:
    """A run ended early: the world first (told to stop, it publishes its last clock, `end: stopped`), then
    the monitor gets the time to record that and close the record itself; the rest are stopped after."""
    world.expected_exit = True
    fleet.signal(world, signal.SIGCONT)
    fleet.signal(world, signal.SIGTERM)
    try:
        world.popen.wait(timeout=5)
    except subprocess.TimeoutExpired:
        fleet.signal(world, signal.SIGKILL)
        world.popen.wait()
    mon = fleet.find("monitor")
    if mon is not None and mon.popen.poll() is None:
        with contextlib.suppress(subprocess.TimeoutExpired):
            mon.popen.wait(timeout=monitor_wait_s)
    fleet.stop_all()


class _Progress:
    def __init__(self, enabled: bool, total_s: float, log_lines: bool = True) -> None:
        self.enabled = enabled
        self.log_lines = log_lines  # without a bar, a `t = ...` line every 5 s
        self.last = 0.0
        self.wall0 = time.monotonic()
        self.bar: Any = None
        if enabled:
            self.bar = Progress(TextColumn("mission"), BarColumn(), TextColumn("t = {task.completed:.1f} s"),
                                TextColumn("{task.fields[info]}"), TimeElapsedColumn(), transient=True)
            self.task = self.bar.add_task("mission", total=total_s, info="")
            self.bar.start()

    def update(self, t: float, alive: int, n: int) -> None:
        wall = time.monotonic() - self.wall0
        info = f"{alive}/{n} agents, {t / wall:.1f}x real time" if wall > 0 and t > 0 else "starting"
        if self.bar is not None:
            self.bar.update(self.task, completed=t, info=info)
        elif self.log_lines and time.monotonic() - self.last > 5.0:
            self.last = time.monotonic()
            log.info("t = %.1f s (%s)", t, info)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()
