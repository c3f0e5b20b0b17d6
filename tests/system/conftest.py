"""Shared fixtures."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.support import assert_all_gone


@pytest.fixture
def out(tmp_path: Path):
    """A run's output directory; afterwards every process the run started must be gone (killed by PID if not)."""
    d = tmp_path / "run"
    yield d
    assert_all_gone(d)
