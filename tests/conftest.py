"""Tests in two folders: tests/unit (no processes, seconds) and tests/system (real processes on 127.0.0.1).

Every test under tests/system is marked `system`, so `pytest -m "not system"` runs the unit suite alone.
"""

from __future__ import annotations

from pathlib import Path

import pytest

_SYSTEM = Path(__file__).parent / "system"


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if _SYSTEM in Path(str(item.fspath)).parents:
            item.add_marker(pytest.mark.system)
