"""Tests in two folders: tests/unit (no processes, seconds) and tests/system (real processes on 127.0.0.1).

Every test under tests/system is marked `system`, so `pytest -m "not system"` runs the unit suite alone. Two more
markers say where a system test can run (deploy/run_tests.sh, docs/testing.md):
- `parallel`: no launch, no router, no wall-clock bound (the engine in-process, commands on records, refusals):
  it runs beside the unit tests, on every CPU (pytest-xdist);
- `realtime`: it holds only if the machine keeps the clock's pace (the realtime clock, ROS 2 mode, a bound in wall
  seconds): it runs alone, after the others; `-m "not realtime"` leaves them out on a loaded machine.
The rest of tests/system (lockstep launches: exact whatever the load) runs one test at a time.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import settings

# Property tests have no deadline per example: the suite runs beside other work (part 1 on every CPU), and a slow
# example is not a wrong one.
settings.register_profile("suite", deadline=None)
settings.load_profile("suite")

_SYSTEM = Path(__file__).parent / "system"


MARKERS = (
    "parallel: a system test with no launch, no router and no wall-clock bound: runs beside the unit tests",
    "realtime: holds only if the machine keeps the clock's pace: runs alone, after the other system tests",
)


def pytest_configure(config: pytest.Config) -> None:
    for line in MARKERS:
        config.addinivalue_line("markers", line)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if _SYSTEM in Path(str(item.fspath)).parents:
            item.add_marker(pytest.mark.system)
