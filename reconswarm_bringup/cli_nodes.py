"""The top floor's process commands: `reconswarm router` and `reconswarm flood` (the roles' own, `agent`, `simworld`
and `monitor record`, live in agent/cli.py, simworld/cli.py and monitor/cli.py). All take the zenoh options
of README.md (`--connect`, `--listen`, `--mode`, `--zenoh-config`) from reconswarm/cli/options.py.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Annotated

import typer

from reconswarm.cli.options import Connect, Listen, Mode, ZConfig, run_process
from reconswarm.net.runtime.session import ZenohOptions, serving

log = logging.getLogger("reconswarm.router")


def router_cmd(
    listen: Listen = None, connect: Connect = None, zenoh_config: ZConfig = None,
) -> None:
    """A zenoh router (Python-hosted) for local and multi-host runs; default tcp/127.0.0.1:7447. It forwards no
    payload over the wire's 1 MiB limit (unless its --zenoh-config sets a low_pass_filter of its own)."""
    from reconswarm.net.runtime.session import DEFAULT_ROUTER

    def go() -> int:
        opts = ZenohOptions.build(connect, listen or ([] if zenoh_config else [DEFAULT_ROUTER]), "router", zenoh_config)
        with serving(opts, "router", timeout_s=5.0) as (_session, stop):
            log.info("router up: listening on %s", ", ".join(opts.listen) or "(config file)")
            while not stop.stopped:
                time.sleep(0.1)
        return 0

    run_process(go)


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

    run_process(go)


def register(app: typer.Typer) -> None:
    app.command("router")(router_cmd)
    app.command("flood", hidden=False)(flood_cmd)
