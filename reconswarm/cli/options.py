"""The options and the process wrapper of the process commands (`agent`, `simworld`, `monitor record`, `router`,
`flood`): the zenoh options of README.md (`--connect`, `--listen`, `--mode`, `--zenoh-config`), `--run`,
`--ros2` and `--ros-domain-id`, and `run_process`, which runs a process's main with logging, the parent watch and
one-line errors."""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Annotated

import typer

from reconswarm.cli.console import fail
from reconswarm.errors import BadInput, ReconswarmError
from reconswarm.net.ros2.ros2 import resolve_domain_id
from reconswarm.net.runtime.lifecycle import bind_to_parent, setup_logging

Connect = Annotated[list[str] | None, typer.Option("--connect", help="Zenoh endpoint to connect to (repeatable).")]
Listen = Annotated[list[str] | None, typer.Option("--listen", help="Zenoh endpoint to listen on (repeatable).")]
Mode = Annotated[str, typer.Option("--mode", help="Zenoh mode: peer | client | router.")]
ZConfig = Annotated[Path | None, typer.Option("--zenoh-config", help="Zenoh JSON5 configuration file.")]
RunId = Annotated[str | None, typer.Option("--run", help="Run id in key expressions (default: the scenario name).")]
Ros2 = Annotated[bool, typer.Option("--ros2", help="The motion interface as ROS 2 topics (odom, cmd_vel) over Zenoh.")]
RosDomain = Annotated[int | None, typer.Option("--ros-domain-id", metavar="D",
                                               help="ROS 2 domain (default: ROS_DOMAIN_ID, else 0).")]


def ros2_domain(ros2: bool, option: int | None) -> int | None:
    """The ROS 2 domain in force (None: ROS 2 mode off)."""
    if option is not None and not ros2:
        raise BadInput("--ros-domain-id: only with --ros2")
    return resolve_domain_id(option, os.environ) if ros2 else None


PROFILE_ENV = "RECONSWARM_PROFILE"  # a directory: every node process dumps its cProfile stats there


@contextlib.contextmanager
def profiled(module: str) -> Iterator[None]:
    """RECONSWARM_PROFILE=DIR: cProfile stats of the body dumped to DIR/MODULE-PID.prof (the directory is made if
    missing). A dump that fails is one warning line, never the process's exit code: the work is done by then."""
    prof_dir = os.environ.get(PROFILE_ENV)
    if not prof_dir:
        yield
        return
    import cProfile

    prof = cProfile.Profile()
    prof.enable()
    try:
        yield
    finally:
        prof.disable()
        path = Path(prof_dir) / f"{module}-{os.getpid()}.prof"
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            prof.dump_stats(str(path))
        except OSError as exc:
            logging.getLogger("reconswarm").warning("%s=%s: profile not written (%s)", PROFILE_ENV, prof_dir,
                                                    exc.strerror or exc)


def run_process(fn: Callable[[], int]) -> None:
    """Run a node process's main: logging set up, the process ends with its parent, a ReconswarmError is one
    line and its exit code, else the main's exit code. RECONSWARM_PROFILE=DIR: cProfile stats dumped to
    DIR/MODULE-PID.prof (MODULE: the command's, e.g. agent.cli; `profiled`)."""
    setup_logging()
    bind_to_parent()
    try:
        with profiled(fn.__module__):
            code = fn()
    except ReconswarmError as exc:
        fail(exc)
        return
    raise typer.Exit(code)
