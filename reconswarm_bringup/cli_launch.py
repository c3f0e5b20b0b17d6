"""`reconswarm launch` (what `deploy/run_local.sh` runs): the mission as separate processes over Zenoh."""

from __future__ import annotations

import logging
import os
import sys
from pathlib import Path
from typing import Annotated

import typer

from reconswarm.cli import help_style, outputs
from reconswarm.cli.console import fail, set_debug
from reconswarm.cli.options import PROFILE_ENV
from reconswarm.errors import BadInput, ReconswarmError
from reconswarm_bringup import outdir
from reconswarm_bringup.fleet import ROOT

help_style.install()

PROG = {"name": "reconswarm launch"}  # the error lines' prefix: the command the user ran (`run_local` from the script)
FOXGLOVE_PORT = 8765  # `--foxglove` without a value
REALTIME_SPEED = 1.0  # --clock realtime (and --ros2) by default: real time, as a robot base runs


def optional_values(argv: list[str]) -> list[str]:
    """`--foxglove` takes an optional value: without one (last, or followed by another option) it means the
    default port, which is inserted here for the parser."""
    out = []
    for i, arg in enumerate(argv):
        out.append(arg)
        if arg == "--foxglove" and (i + 1 == len(argv) or argv[i + 1].startswith("-")):
            out.append(str(FOXGLOVE_PORT))
    return out


def check_zenoh_mode(mode: str, secure: bool, hosts: int) -> None:
    """--zenoh-mode: auto, client or peer; peer on a plain run of one host only (secure mode's access control and each
    host's own router hold only if every sample goes through the routers)."""
    if mode not in ("auto", "client", "peer"):
        raise BadInput(f"--zenoh-mode: expected auto, client or peer, got {mode!r}")
    if mode == "peer" and secure:
        raise BadInput("--zenoh-mode peer: not with --secure (its access control is in the router: every sample must "
                       "go through it)")
    if mode == "peer" and hosts != 1:
        raise BadInput("--zenoh-mode peer: not with --hosts 2 (each host's processes reach the other host through "
                       "their own router)")


def launch_cmd(
    agents: Annotated[int | None, typer.Option("-n", "--agents",
        help="Generate a scenario with N agents (instead of -s).")] = None,
    scenario: Annotated[Path | None, typer.Option("-s", "--scenario",
        help="Scenario TOML (default: the paper's).")] = None,
    out: Annotated[Path | None, typer.Option("-o", "--out", metavar="DIR",
        help="Output directory (default: a new runs/YYYYMMDD-HHMMSS in the project; runs/latest links to the "
             "newest).")] = None,
    clock: Annotated[str | None, typer.Option("--clock", help="lockstep (default) | realtime")] = None,
    speed: Annotated[float | None, typer.Option("--speed",
        help="Realtime: simulated seconds per wall second (default 1, real time).")] = None,
    planner: Annotated[str | None, typer.Option(
        "--planner", help="reconfigurable | virtual-leader | orca | hrvo | hl | social-force")] = None,
    router: Annotated[str | None, typer.Option("--router", metavar="EP",
        help="Router endpoint (default tcp/127.0.0.1:7447); one is started there unless one listens.")] = None,
    secure: Annotated[bool, typer.Option("--secure",
        help="Mutual TLS, per-process credentials and access control.")] = False,
    fault: Annotated[list[str] | None, typer.Option("--fault", metavar="SPEC",
        help="Inject a fault (repeatable), e.g. kill:agent:3@60; see docs/faults.md.")] = None,
    hosts: Annotated[int, typer.Option("--hosts",
        help="2: two hosts as network namespaces, each with its own router (needs root).")] = 1,
    timeout: Annotated[float | None, typer.Option("--timeout",
        help="Give up after this many seconds of wall time (exit 3).")] = None,
    foxglove: Annotated[int | None, typer.Option("--foxglove", metavar="[PORT]",
        help=f"Also serve the run live to the Foxglove app on ws://127.0.0.1:PORT (default {FOXGLOVE_PORT}).")] = None,
    ros2: Annotated[bool, typer.Option("--ros2",
        help="The robots' motion interface as ROS 2 topics over Zenoh (odom, cmd_vel); implies --clock realtime.")
        ] = False,
    ros_domain_id: Annotated[int | None, typer.Option("--ros-domain-id", metavar="D",
        help="ROS 2 domain (default: ROS_DOMAIN_ID, else 0).")] = None,
    agents_per_process: Annotated[str, typer.Option("--agents-per-process", metavar="K|auto",
        help="Agents per process (one zenoh session each; default 1); auto: one process for up to 48 agents, "
             "then one per CPU.")] = "1",
    no_pin_cpus: Annotated[bool, typer.Option("--no-pin-cpus",
        help="Do not pin: the scheduler may run any agent process on any CPU (by default each agent process is "
             "held to one CPU, the CPUs in turn); e.g. while other work shares the machine.")] = False,
    zenoh_mode: Annotated[str, typer.Option("--zenoh-mode", metavar="auto|client|peer",
        help="The processes' zenoh mode: client (every sample through the router), peer (samples straight from "
             "process to process; the router for discovery and outside tools); auto (default): peer for agent "
             "hosts in an open-mode run of at most 8 processes on one host, else client.")] = "auto",
    as_json: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
    no_progress: Annotated[bool, typer.Option("--no-progress", help="No progress bar, nor the lines logged instead.")
                           ] = False,
    debug: Annotated[bool, typer.Option("--debug", help="Show tracebacks.")] = False,
) -> None:
    """Run the mission as separate processes over Zenoh on this machine (router, simworld, monitor, agents)."""
    from reconswarm.net.ros2.ros2 import resolve_domain_id
    from reconswarm.scenario.model import PLANNERS
    from reconswarm_bringup import faults as faults_mod
    from reconswarm_bringup import packing, validate
    from reconswarm_bringup.config import LaunchConfig
    from reconswarm_bringup.launcher import run

    prog = PROG["name"]
    set_debug(debug)
    logging.basicConfig(level=logging.DEBUG if debug else logging.INFO, format=f"{prog}: %(message)s")
    try:
        latest = out is None
        if out is None:
            out = outdir.new_run_dir(ROOT / "runs")
        out = out.resolve()  # (relative to the directory the command was run from)
        profile_dir()
        speed = speed if speed is not None else REALTIME_SPEED
        if ros2 and clock == "lockstep":
            raise BadInput("--ros2: runs on the realtime clock only (ROS 2 topics carry no tick), not --clock lockstep")
        clock = clock or ("realtime" if ros2 else "lockstep")
        if clock not in ("lockstep", "realtime"):
            raise BadInput(f"--clock: expected lockstep or realtime, got {clock!r}")
        if planner is not None and planner not in PLANNERS:
            raise BadInput(f"--planner: expected one of {', '.join(PLANNERS)}, got {planner!r}")
        if foxglove is not None and not 1 <= foxglove <= 65535:
            raise BadInput(f"--foxglove: port must be in 1..65535, got {foxglove}")
        per_process = packing.parse(agents_per_process)
        if ros_domain_id is not None and not ros2:
            raise BadInput("--ros-domain-id: only with --ros2")
        domain = resolve_domain_id(ros_domain_id, os.environ) if ros2 else None
        if hosts not in (1, 2):
            raise BadInput(f"--hosts: expected 1 or 2, got {hosts}")
        check_zenoh_mode(zenoh_mode, secure=secure, hosts=hosts)
        validate.launch(agents=agents, scenario=scenario, out=out, timeout_s=timeout, speed=speed,
                        router=router, hosts=hosts, available_mb=validate.available_memory_mb(),
                        per_process=per_process)
        cfg = LaunchConfig(out=out, latest=latest, scenario=scenario, agents=agents, clock=clock, speed=speed,
                           planner=planner, router=router, secure=secure,
                           faults=tuple(faults_mod.parse(f) for f in fault or []), timeout_s=timeout,
                           progress=not no_progress, as_json=as_json, hosts=hosts,
                           foxglove_port=foxglove, ros_domain_id=domain, agents_per_process=per_process,
                           pin_cpus=not no_pin_cpus, zenoh_mode=zenoh_mode)
        code = run(cfg)
    except ReconswarmError as exc:
        fail(exc, prog)
        return
    raise typer.Exit(code)


def profile_dir() -> None:
    """RECONSWARM_PROFILE=DIR (every process of the run dumps its cProfile stats there): DIR relative to the
    directory the command was run from, made if missing, checked before the run starts."""
    raw = os.environ.get(PROFILE_ENV)
    if not raw:
        return
    where = Path(raw).resolve()
    try:
        where.mkdir(parents=True, exist_ok=True)
        outputs.writable_dir(PROFILE_ENV, where)
    except OSError as exc:
        raise BadInput(f"{PROFILE_ENV}={raw}: cannot write profiles there ({exc.strerror or exc})") from None
    os.environ[PROFILE_ENV] = str(where)  # (the processes run from the project's directory)
    logging.getLogger("reconswarm.launch").info("profiles: %s/MODULE-PID.prof, one per process", where)


def register(app: typer.Typer) -> None:
    app.command("launch")(launch_cmd)


def main() -> None:
    """`python -m reconswarm_bringup.cli_launch ARGS` = `reconswarm launch ARGS` (deploy/run_local.sh)."""
    PROG["name"] = "run_local"
    app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)
    app.command()(launch_cmd)
    try:
        code = app(args=optional_values(sys.argv[1:]), prog_name="deploy/run_local.sh", standalone_mode=False)
    except Exception as exc:
        if not (hasattr(exc, "format_message") and hasattr(exc, "exit_code")):
            raise
        # A usage error (a value typer cannot parse, an unknown option): one line, not the usage and a box.
        print(f"{PROG['name']}: error: {exc.format_message()}", file=sys.stderr)
        sys.exit(exc.exit_code)
    sys.exit(code if isinstance(code, int) else 0)


if __name__ == "__main__":
    main()
