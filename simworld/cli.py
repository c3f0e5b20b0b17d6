"""`reconswarm simworld` (= `python -m simworld`): parses the options into a SimworldConfig and calls
simworld.process.run(config). reconswarm_bringup/cli.py registers `simworld_cmd` as the `simworld` command;
`app` is the same command alone, for `python -m simworld`."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from reconswarm.cli import help_style
from reconswarm.cli.options import Connect, Listen, Mode, Ros2, RosDomain, RunId, ZConfig, ros2_domain, run_process
from reconswarm.net.runtime.session import ZenohOptions
from reconswarm.net.wire.wire import ClockMode

help_style.install()


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
        return run(SimworldConfig(scenario, zopts, mode_, speed, run_id, start_timeout,
                                  ros2_domain(ros2, ros_domain_id)))

    run_process(go)


app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)
app.command("simworld")(simworld_cmd)
