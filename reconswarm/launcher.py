"""The main job behind `deploy/run_local.sh`: one run of the mission as separate processes.

Starts a zenoh router (unless --router names one), the monitor, one process per agent and simworld,
each with its log in OUTDIR/logs/ and a line in OUTDIR/processes.tsv (role, id, pid) as it starts;
follows the clock to show progress and to fire faults at simulated times; restarts the monitor if it
dies; when the world ends the mission it lets everyone finish, stops what is left, prints the summary
and returns the documented exit code. SIGINT / SIGTERM stop everything; every child is also bound to
this process (PR_SET_PDEATHSIG) so none outlives it.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from reconswarm import faults as faults_mod
from reconswarm import wire
from reconswarm.errors import BadInput, ProcessFailure, ReconswarmError
from reconswarm.scenario import Scenario, load, to_toml
from reconswarm.session import DEFAULT_ROUTER, ZenohOptions, open_session

log = logging.getLogger("reconswarm.launch")
ROOT = Path(__file__).resolve().parent.parent
PAPER = ROOT / "deploy" / "scenarios" / "paper.toml"
ZENOH_RUNTIME = "(" + ", ".join(f"{pool}: (worker_threads: 1)" for pool in ("app", "acc", "tx", "rx", "net")) + ")"


@dataclass(frozen=True)
class LaunchConfig:
    out: Path
    scenario: Path | None = None
    agents: int | None = None
    clock: str = "lockstep"
    speed: float = 10.0
    planner: str | None = None
    router: str | None = None
    secure: bool = False
    faults: tuple[faults_mod.Fault, ...] = ()
    timeout_s: float | None = None
    progress: bool = True
    as_json: bool = False
    start_timeout_s: float = 120.0
    hosts: int = 1


@dataclass
class Proc:
    role: str
    id: str
    args: list[str]
    popen: subprocess.Popen[bytes]
    log_path: Path
    prefix: list[str] = field(default_factory=list)  # e.g. `ip netns exec NS` for host B
    expected_exit: bool = False  # stopped on purpose (a fault or the end of the run)


@dataclass
class Fleet:
    """The run's processes: started with subprocess (no fork of a zenoh-holding process), logged, tracked."""

    out: Path
    env: dict[str, str]
    procs: list[Proc] = field(default_factory=list)
    zopt: Any = None  # (role, id) -> (command prefix, zenoh args), set by run()
    router_env: dict[str, str] | None = None  # the routers' environment, when it differs from env

    def start(self, role: str, ident: str, args: list[str], prefix: list[str] | None = None) -> Proc:
        logs = self.out / "logs"
        logs.mkdir(parents=True, exist_ok=True)
        name = role if ident == "-" else f"{role}-{ident}"
        log_path = logs / f"{name}.log"
        fh = log_path.open("ab")
        popen = subprocess.Popen([*(prefix or []), sys.executable, "-m", "reconswarm.cli", *args], stdout=fh,
                                 stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                 env=self.router_env if role == "router" and self.router_env else self.env,
                                 cwd=str(ROOT))
        fh.close()
        proc = Proc(role, ident, args, popen, log_path, list(prefix or []))
        self.procs.append(proc)
        with (self.out / "processes.tsv").open("a") as tsv:
            tsv.write(f"{role}\t{ident}\t{popen.pid}\n")
        return proc

    def find(self, role: str, ident: str = "-") -> Proc | None:
        live = [p for p in self.procs if p.role == role and p.id == ident]
        return live[-1] if live else None

    def restart(self, proc: Proc) -> Proc:
        return self.start(proc.role, proc.id, proc.args, proc.prefix)

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


def _port_free(endpoint: str) -> bool:
    proto, _, addr = endpoint.partition("/")
    if proto not in ("tcp", "tls"):
        return True
    host, _, port = addr.rpartition(":")
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host.strip("[]"), int(port)))
        except OSError:
            return False
    return True


def prepare_scenario(cfg: LaunchConfig) -> tuple[Scenario, Path]:
    """The scenario of the run, written to OUTDIR/scenario.toml so every process reads the same file."""
    if cfg.scenario is not None and cfg.agents is not None:
        raise BadInput("-n/--agents and -s/--scenario: give one (-n generates a scenario)")
    if cfg.agents is not None:
        from reconswarm.generate import generate

        s = generate(cfg.agents, max(1, min(10, cfg.agents // 5 + 2)), 0)
    else:
        s = load(cfg.scenario or PAPER)
    if cfg.planner is not None:
        s = s.with_planner(cfg.planner)
    path = cfg.out / "scenario.toml"
    path.write_text(to_toml(s))
    return s, path


class ClockWatch:
    """Follows the run's clock (and events) on its own zenoh session: progress and fault timing.

    The clock lands in a one-slot ring (only the latest matters), events in a queue; both are read when
    the launcher polls, so this process does not wake for every tick.
    """

    def __init__(self, run: str, zopts: ZenohOptions) -> None:
        import zenoh

        self.keys = wire.Keys(run)
        self.session = open_session(zopts, "run_local")
        self.clock_sub = self.session.declare_subscriber(self.keys.clock, zenoh.handlers.RingChannel(1))
        self.event_sub = self.session.declare_subscriber(self.keys.event, zenoh.handlers.FifoChannel(10_000))
        self.t = 0.0
        self.k = -1
        self.alive = 0
        self.end: wire.Clock | None = None
        self.events: list[wire.Event] = []

    def poll(self) -> None:
        with contextlib.suppress(wire.WireError):
            sample = self.clock_sub.try_recv()
            if sample is not None:
                c = wire.clock_from_wire(sample.payload.to_bytes())
                if c.k >= self.k:
                    self.t, self.k, self.alive = c.t, c.k, len(c.alive)
                if c.end:
                    self.end = c
        while (sample := self.event_sub.try_recv()) is not None:
            with contextlib.suppress(wire.WireError):
                self.events.append(wire.event_from_wire(sample.payload.to_bytes()))

    def close(self) -> None:
        self.session.close()


@dataclass
class Net:
    """Where the routers run and how each process reaches one."""

    watch: ZenohOptions  # the launcher's own session (progress, fault timing)
    routers: list[tuple[str, list[str], list[str]]]  # (id, router args, command prefix) to start
    reach: dict[tuple[str, str], tuple[list[str], list[str]]]  # (role, id) -> (prefix, zenoh args)
    default: list[str]
    hosts: Any = None

    def zopt(self, role: str, ident: str = "-") -> tuple[list[str], list[str]]:
        return self.reach.get((role, ident), ([], self.default))


def plan_network(cfg: LaunchConfig, s: Scenario) -> Net:
    endpoint = cfg.router or DEFAULT_ROUTER
    if cfg.secure and cfg.hosts > 1:
        raise BadInput("--secure with --hosts 2 is not supported")
    if cfg.secure:
        from reconswarm import secure

        sec = secure.create(cfg.out / "secrets", s, endpoint)
        reach: dict[tuple[str, str], tuple[list[str], list[str]]] = {
            ("monitor", "-"): ([], ["--zenoh-config", str(sec.config_for("monitor", "-"))]),
                 ("simworld", "-"): ([], ["--zenoh-config", str(sec.config_for("simworld", "-"))]),
                 ("flood", "-"): ([], ["--zenoh-config", str(cfg.out / "secrets" / "intruder.json5")])}
        reach |= {("agent", str(a.id)): ([], ["--zenoh-config", str(sec.config_for("agent", str(a.id)))])
                  for a in s.agents}
        if not _port_free(sec.endpoint):  # a router already there holds another run's CA: it cannot serve us
            raise ProcessFailure(f"router: {sec.endpoint} is in use; secure mode starts its own router")
        routers: list[tuple[str, list[str], list[str]]] = [
            ("-", ["router", "--zenoh-config", str(sec.router_config)], [])]
        return Net(sec.observer_options(), routers, reach, [])
    if cfg.hosts == 2:
        from reconswarm import netns

        hosts = netns.TwoHosts.for_run(os.getpid())
        hosts.create()
        netns.ACTIVE.append(hosts)
        port = endpoint.rpartition(":")[2]
        ep_a, ep_b = f"tcp/{hosts.ip_a}:{port}", f"tcp/{hosts.ip_b}:{port}"
        on_b = [a.id for a in s.agents][len(s.agents) // 2:]
        reach = {("agent", str(a)): (hosts.exec_prefix(), ["--connect", ep_b]) for a in on_b}
        routers = [("A", ["router", "--listen", ep_a], []),
                   ("B", ["router", "--listen", ep_b, "--connect", ep_a], hosts.exec_prefix())]
        log.info("two hosts: A (this namespace, router %s: simworld, monitor, agents %s) and B (%s, router %s: "
                 "agents %s)", ep_a, [a.id for a in s.agents if a.id not in on_b], hosts.ns_b, ep_b, on_b)
        return Net(ZenohOptions.build([ep_a], None, "client", None), routers, reach, ["--connect", ep_a], hosts)
    if _port_free(endpoint):
        routers = [("-", ["router", "--listen", endpoint], [])]
    elif cfg.router is None:
        raise ProcessFailure(f"router: {endpoint} is in use (another run?); stop it or pass --router EP")
    else:
        log.info("using the router already listening on %s", endpoint)
        routers = []
    return Net(ZenohOptions.build([endpoint], None, "client", None), routers, {}, ["--connect", endpoint])


def run(cfg: LaunchConfig) -> int:
    cfg.out.mkdir(parents=True, exist_ok=True)
    for stale in ("processes.tsv", "faults.tsv", "run.db", "run.db-wal", "run.db-shm"):
        (cfg.out / stale).unlink(missing_ok=True)
    s, scen_path = prepare_scenario(cfg)
    if cfg.clock not in ("lockstep", "realtime"):
        raise BadInput(f"--clock: expected lockstep or realtime, got {cfg.clock!r}")
    if any(f.action == "partition" for f in cfg.faults) and cfg.hosts != 2:
        raise BadInput("--fault partition@...: needs --hosts 2 (two hosts to cut apart)")
    router_env = dict(os.environ, RECONSWARM_DIE_WITH_PARENT=str(os.getpid()), PYTHONUNBUFFERED="1")
    env = dict(router_env)
    # One worker thread per zenoh runtime pool in the clients: a process here handles a few hundred messages
    # a second, and fewer threads mean fewer hand-offs (measured ~3 % less CPU on the paper mission). Not in
    # routers: a router whose one tx thread waits on a dead link (a partition, until the lease runs out and
    # after) stops forwarding for everyone else too; measured: the whole of host A stalled for the 10 s cut.
    env.setdefault("ZENOH_RUNTIME", ZENOH_RUNTIME)
    fleet = Fleet(cfg.out, env, router_env=router_env)
    stop_sig: list[int] = []

    def on_signal(signum: int, _frame: Any) -> None:
        stop_sig.append(signum)

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, on_signal)

    net: Net | None = None
    watch: ClockWatch | None = None
    code = 3
    try:
        net = plan_network(cfg, s)
        fleet.zopt = net.zopt
        for ident, args, prefix in net.routers:
            fleet.start("router", ident, args, prefix)
        prefix, zargs = net.zopt("monitor")
        mon = fleet.start("monitor", "-", ["monitor", "record", "--scenario", str(scen_path), "--db",
                                           str(cfg.out / "run.db"), "--no-live", *zargs], prefix)
        for a in s.agents:
            prefix, zargs = net.zopt("agent", str(a.id))
            fleet.start("agent", str(a.id), ["agent", "--id", str(a.id), "--scenario", str(scen_path), *zargs], prefix)
        prefix, zargs = net.zopt("simworld")
        world = fleet.start("simworld", "-", ["simworld", "--scenario", str(scen_path), "--clock", cfg.clock,
                                              "--speed", str(cfg.speed), "--start-timeout", str(cfg.start_timeout_s),
                                              *zargs], prefix)
        watch = ClockWatch(s.meta.name, net.watch)
        code = _supervise(cfg, s, fleet, world, mon, watch, stop_sig)
    finally:
        if watch is not None:
            watch.close()
        fleet.stop_all()
        if net is not None and net.hosts is not None:
            from reconswarm import netns

            net.hosts.delete()
            netns.ACTIVE.clear()
    if stop_sig:
        log.warning("stopped by signal %d", stop_sig[0])
        return 128 + stop_sig[0]
    return code


def _supervise(cfg: LaunchConfig, s: Scenario, fleet: Fleet, world: Proc, mon: Proc, watch: ClockWatch,
               stop_sig: list[int]) -> int:
    from reconswarm import chaos

    pending = sorted(cfg.faults, key=lambda f: f.at_s)
    timers: list[tuple[float, Any]] = []  # (wall time, action)
    wall0 = time.monotonic()
    bar = _Progress(cfg.progress and sys.stderr.isatty() and not cfg.as_json, s.meta.duration_s)
    crashed: list[str] = []
    try:
        while not stop_sig:
            watch.poll()
            now = time.monotonic()
            while pending and watch.k >= 0 and watch.t >= pending[0].at_s and watch.end is None:
                f = pending.pop(0)
                log.warning("fault: %s", f.describe())
                with (cfg.out / "faults.tsv").open("a") as tsv:
                    tsv.write(f"{time.time():.6f}\t{watch.t:.3f}\t{f.describe()}\n")
                timers += chaos.inject(f, fleet, watch, cfg)
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
                        log.warning("monitor died (exit %s): restarting it", rc)
                        mon = fleet.restart(p)
                    elif rc != 0 and watch.end is None:
                        crashed.append(f"{p.role} {p.id} exited {rc}")
                        log.warning("%s %s exited with %s", p.role, p.id, rc)
            bar.update(watch.t, watch.alive, len(s.agents))
            if world.popen.poll() is not None:
                break
            if cfg.timeout_s is not None and now - wall0 > cfg.timeout_s:
                log.error("timeout after %.0f s of wall time", cfg.timeout_s)
                return 3
            time.sleep(0.05)
        if stop_sig:
            return 128 + stop_sig[0]
        rc = world.popen.returncode
        if rc != 0:
            tail = world.log_path.read_text(errors="replace").strip().splitlines()[-1:]
            raise ProcessFailure(f"simworld exited {rc}: {tail[0] if tail else ''} (see {world.log_path})")
        try:  # the monitor writes the last ticks and closes the record
            mon.popen.wait(timeout=15)
        except subprocess.TimeoutExpired:
            log.warning("monitor did not finish in time")
        deadline = time.monotonic() + 5
        for p in fleet.procs:
            if p.role == "agent" and p.popen.poll() is None:
                with contextlib.suppress(subprocess.TimeoutExpired):
                    p.popen.wait(timeout=max(0.1, deadline - time.monotonic()))
    finally:
        bar.close()
    return _report(cfg, crashed)


def _report(cfg: LaunchConfig, crashed: list[str]) -> int:
    from monitor.record import RunRecord
    from monitor.summary import render, summarize
    from reconswarm.cli import mission_exit_code

    db = cfg.out / "run.db"
    rec = RunRecord(db)
    summary = summarize(rec)
    rec.close()
    if cfg.as_json:
        sys.stdout.write(json.dumps(summary, indent=2) + "\n")
    else:
        from rich.console import Console

        Console().print(render(summary))
        print(f"record: {db}\nlogs:   {cfg.out / 'logs'}")
    if crashed:
        log.error("processes failed: %s", "; ".join(crashed))
        return 3
    return mission_exit_code(summary)


class _Progress:
    def __init__(self, enabled: bool, total_s: float) -> None:
        self.enabled = enabled
        self.last = 0.0
        self.wall0 = time.monotonic()
        self.bar: Any = None
        if enabled:
            from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

            self.bar = Progress(TextColumn("mission"), BarColumn(), TextColumn("t = {task.completed:.1f} s"),
                                TextColumn("{task.fields[info]}"), TimeElapsedColumn(), transient=True)
            self.task = self.bar.add_task("mission", total=total_s, info="")
            self.bar.start()

    def update(self, t: float, alive: int, n: int) -> None:
        wall = time.monotonic() - self.wall0
        info = f"{alive}/{n} agents, {t / wall:.1f}x real time" if wall > 0 and t > 0 else "starting"
        if self.bar is not None:
            self.bar.update(self.task, completed=t, info=info)
        elif time.monotonic() - self.last > 5.0:
            self.last = time.monotonic()
            log.info("t = %.1f s (%s)", t, info)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="deploy/run_local.sh",
                                 description="Run the mission as separate processes over Zenoh on this machine.")
    ap.add_argument("-n", "--agents", type=int, help="generate a scenario with N agents (instead of -s)")
    ap.add_argument("-s", "--scenario", type=Path, help="scenario TOML (default: the paper's)")
    ap.add_argument("-o", "--out", type=Path, default=ROOT / "runs" / "latest", help="output directory")
    ap.add_argument("--clock", default="lockstep", choices=["lockstep", "realtime"])
    ap.add_argument("--speed", type=float, default=10.0, help="realtime: simulated seconds per wall second")
    ap.add_argument("--planner", choices=["reconfigurable", "virtual-leader"])
    ap.add_argument("--router", metavar="EP",
                    help="router endpoint (default tcp/127.0.0.1:7447); one is started there unless one listens")
    ap.add_argument("--secure", action="store_true", help="mutual TLS, per-process credentials and access control")
    ap.add_argument("--fault", action="append", default=[], metavar="SPEC",
                    help="inject a fault (repeatable), e.g. kill:agent:3@60; see the README")
    ap.add_argument("--hosts", type=int, default=1, choices=[1, 2],
                    help="2: two hosts as network namespaces, each with its own router (needs root)")
    ap.add_argument("--timeout", type=float, help="give up after this many seconds of wall time (exit 3)")
    ap.add_argument("--json", action="store_true", help="print the summary as JSON")
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--debug", action="store_true")
    try:
        args = ap.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0) and 2
    logging.basicConfig(level=logging.DEBUG if args.debug else logging.INFO, format="run_local: %(message)s")
    try:
        if args.agents is not None and args.agents < 1:
            raise BadInput(f"-n: must be >= 1, got {args.agents}")
        if not args.speed > 0:
            raise BadInput(f"--speed: must be > 0, got {args.speed}")
        cfg = LaunchConfig(out=args.out.resolve(), scenario=args.scenario, agents=args.agents, clock=args.clock,
                           speed=args.speed, planner=args.planner, router=args.router, secure=args.secure,
                           faults=tuple(faults_mod.parse(f) for f in args.fault), timeout_s=args.timeout,
                           progress=not args.no_progress, as_json=args.json, hosts=args.hosts)
        return run(cfg)
    except ReconswarmError as exc:
        if args.debug:
            raise
        print(f"run_local: error: {exc}", file=sys.stderr)
        return exc.exit_code


if __name__ == "__main__":
    sys.exit(main())
