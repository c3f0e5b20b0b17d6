"""`reconswarm agent` (= `python -m agent`): parses the options into an AgentConfig and calls
agent.process.run(config). reconswarm_bringup/cli.py registers `agent_cmd` as the `agent` command; `app` is the
same command alone, for `python -m agent`."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from reconswarm.cli import help_style
from reconswarm.cli.options import Connect, Listen, Mode, Ros2, RosDomain, RunId, ZConfig, ros2_domain, run_process
from reconswarm.net.runtime.session import ZenohOptions

help_style.install()


def agent_cmd(
    scenario: Annotated[Path, typer.Option("--scenario", help="Scenario TOML file.")],
    agent_id: Annotated[list[str] | None, typer.Option("--id", metavar="I",
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
                               ros2_domain_id=ros2_domain(ros2, ros_domain_id)))

    run_process(go)


app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)
app.command("agent")(agent_cmd)
