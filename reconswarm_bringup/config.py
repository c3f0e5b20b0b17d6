"""The launcher's configuration (what `deploy/run_local.sh` was asked to do)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from reconswarm_bringup.faults import Fault


@dataclass(frozen=True)
class LaunchConfig:
    out: Path
    scenario: Path | None = None
    agents: int | None = None
    clock: str = "lockstep"
    speed: float = 1.0  # realtime: simulated seconds per wall second (real time unless asked otherwise)
    planner: str | None = None
    router: str | None = None
    secure: bool = False
    faults: tuple[Fault, ...] = ()
    timeout_s: float | None = None
    progress: bool = True
    as_json: bool = False
    start_timeout_s: float = 120.0
    hosts: int = 1
    foxglove_port: int | None = None  # the monitor serves the run live on 127.0.0.1:PORT
    ros_domain_id: int | None = None  # ROS 2 mode (None: off) in this domain
    agents_per_process: int | str = 1  # K, or "auto" (reconswarm_bringup/packing.py)
    pin_cpus: bool = True  # agent hosts each on one CPU, the CPUs in turn (reconswarm_bringup/fleet.py)
    latest: bool = False  # out is a run's own directory under runs/: runs/latest is made to link to it
    zenoh_mode: str = "auto"  # the run's processes as zenoh clients of the router, peers (direct samples), or auto
