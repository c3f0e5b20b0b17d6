"""The distributed commands: `reconswarm agent`, `reconswarm simworld`, `reconswarm router`.

Each parses its options into a frozen config and calls its module's run(config); all share the zenoh
options of README.md (`--connect`, `--listen`, `--mode`, `--zenoh-config`).
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Annotated

import typer

from reconswarm.errors import ReconswarmError
from reconswarm.net.session import ZenohOptions, bind_to_parent, serving, setup_logging
from reconswarm.net.wire import ClockMode
from reconswarm_bringup.console import fail

log = logging.getLogger("reconswarm.router")

Connect = Annotated[list[str] | None, typer.Option("--connect", help="Zenoh endpoint to connect to (repeatable).")]
Listen = Annotated[list[str] | None, typer.Option("--listen", help="Zenoh endpoint to listen on (repeatable).")]
Mode = Annotated[str, typer.Option("--mode", help="Zenoh mode: peer | client | router.")]
ZConfig = Annotated[Path | None, typer.Option("--zenoh-config", help="Zenoh JSON5 configuration file.")]
RunId = Annotated[str | None, typer.Option("--run", help="Run id in key expressions (default: the scenario name).")]
Ros2 = Annotated[bool, typer.Option("--ros2", help="The motion interface as ROS 2 topics (odom, cmd_vel) over Zenoh.")]
RosDomain = Annotated[int | None, typer.Option("--ros-domain-id", metavar="D",
                                               help="ROS 2 domain (default: ROS_DOMAIN_ID, else 0).")]


def _domain(ros2: bool, option: int | None) -> int | None:
    """The ROS 2 domain in force (None: ROS 2 mode off)."""
    from reconswarm.errors import BadInput
    from reconswarm.net.ros2 import resolve_domain_id

    if option is not None and not ros2:
        raise BadInput("--ros-domain-id: only with --ros2")
    return resolve_domain_id(option, os.environ) if ros2 else None


def _guard(fn: Callable[[], int]) -> None:
    setup_logging()
    bind_to_parent()
    prof_dir = os.environ.get("RECONSWARM_PROFILE")  # a directory: dump cProfile stats per process
    prof = None
    if prof_dir:
        import cProfile

        prof = cProfile.Profile()
        prof.enable()
    try:
        code = fn()
    except ReconswarmError as exc:
        fail(exc)
        return
    finally:
        if prof is not None:
            prof.disable()
            prof.dump_stats(os.path.join(str(prof_dir), f"{fn.__module__}-{os.getpid()}.prof"))
    raise typer.Exit(code)


def agent_cmd(
    scenario: Annotated[Path, typer.Option("--scenario", help="Scenario TOML file.")],
    agent_id: Annotated[list[int] | None, typer.Option("--id",
        help="This agent's id (from the scenario); repeatable: those agents in this process.")] = None,
    ids: Annotated[str | None, typer.Option("--ids", metavar="1-5,9",
        help="Host these agents in this process (one zenoh session; each keeps its own keys and token).")] = None,
    connect: Connect = None, listen: Listen = None, mode: Mode = "client", zenoh_config: ZConfig = None,
    run_id: RunId = None, ros2: Ros2 = False, ros_domain_id: RosDomain = None,
) -> None:
    """One agent process (or a host of several): plans commands from states, scans and neighbours' announcements."""
    from agent.process import AgentConfig, parse_ids, run

    def go() -> int:
        return run(AgentConfig(parse_ids(agent_id, ids), scenario,
                               ZenohOptions.build(connect, listen, mode, zenoh_config), run_id,
                               ros2_domain_id=_domain(ros2, ros_domain_id)))

    _guard(go)


def simworld_cmd(
    scenario: Annotated[Path, typer.Option("--scenario", help="Scenario TOML file.")],
    clock: Annotated[ClockMode | None, typer.Option("--clock",
        help="How the world advances (default lockstep; realtime with --ros2).")] = None,
    speed: Annotated[float, typer.Option("--speed", help="Realtime: simulated seconds per wall second.")] = 1.0,
    start_timeout: Annotated[float, typer.Option("--start-timeout", help="Seconds to wait for everyone.")] = 60.0,
    connect: Connect = None, listen: Listen = None, mode: Mode = "client", zenoh_config: ZConfig = None,
    run_id: RunId = None, ros2: Ros2 = False, ros_domain_id: RosDomain = None,
) -> None:
    """The world process: unicycle kinematics, range-limited sensing and the clock."""
    from simworld.process import SimworldConfig, run

    def go() -> int:
        zopts = ZenohOptions.build(connect, listen, mode, zenoh_config)
        mode_ = clock or (ClockMode.REALTIME if ros2 else ClockMode.LOCKSTEP)
        return run(SimworldConfig(scenario, zopts, mode_, speed, run_id, start_timeout, _domain(ros2, ros_domain_id)))

    _guard(go)


def router_cmd(
    listen: Listen = None, connect: Connect = None, zenoh_config: ZConfig = None,
) -> None:
    """A zenoh router (Python-hosted) for local and multi-host runs; default tcp/127.0.0.1:7447."""
    from reconswarm.net.session import DEFAULT_ROUTER

    def go() -> int:
        opts = ZenohOptions.build(connect, listen or ([] if zenoh_config else [DEFAULT_ROUTER]), "router", zenoh_config)
        with serving(opts, "router", timeout_s=5.0) as (_session, stop):
            log.info("router up: listening on %s", ", ".join(opts.listen) or "(config file)")
            while not stop.stopped:
                time.sleep(0.1)
        return 0

    _guard(go)


def flood_cmd(
    run_id: Annotated[str, typer.Option("--run", help="Run id whose keys to flood (a launch's OUTDIR/run_id).")],
    count: Annotated[int, typer.Option("--count", help="How many malformed payloads.", min=1)] = 10_000,
    scenario: Annotated[Path | None, typer.Option("--scenario", help="Scenario (for the agent ids).")] = None,
    connect: Connect = None, listen: Listen = None, mode: Mode = "client", zenoh_config: ZConfig = None,
) -> None:
    """Fault injection: publish malformed payloads on every key of a run (each must be dropped and counted)."""
    from reconswarm_bringup.flood import FloodConfig, run

    def go() -> int:
        run(FloodConfig(run_id, scenario, count, ZenohOptions.build(connect, listen, mode, zenoh_config)))
        return 0

    _guard(go)


def register(app: typer.Typer) -> None:
    app.command("agent")(agent_cmd)
    app.command("simworld")(simworld_cmd)
    app.command("router")(router_cmd)
    app.command("flood", hidden=False)(flood_cmd)
