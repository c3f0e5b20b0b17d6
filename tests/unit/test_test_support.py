"""The tests' own helpers (tests/support.py): the port range and the wait for a condition."""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.support import port_range, wait_until


def test_the_port_range_is_shared_out_among_the_workers() -> None:
    assert port_range("") is None
    assert port_range("20000-20999", "", 1) == range(20000, 21000)
    assert port_range("20000-20999", "gw0", 2) == range(20000, 20500)
    assert port_range("20000-20999", "gw1", 2) == range(20500, 21000)
    with pytest.raises(ValueError, match="fewer ports than the 3 test workers"):
        port_range("20000-20001", "gw2", 3)
    for bad in ("20000", "999-2000", "30000-20000", "20000-70000", "a-b"):
        with pytest.raises(ValueError, match="expected A-B"):
            port_range(bad, "", 1)


def test_wait_until_returns_the_value_or_fails_naming_what_it_waited_for() -> None:
    calls = iter([0, [], "ready"])
    assert wait_until(lambda: next(calls), 5.0, "a value", every_s=0.0) == "ready"
    with pytest.raises(AssertionError, match=r"the moon: not within 0\.05 s"):
        wait_until(lambda: False, 0.05, "the moon", every_s=0.01)
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    with pytest.raises(AssertionError, match=r"a sign: the process exited \(0\) first"):
        wait_until(lambda: False, 30.0, "a sign", proc=gone)
