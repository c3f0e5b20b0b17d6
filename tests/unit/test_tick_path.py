"""The tick's serial path: the marks a process keeps (net/runtime/trace.py) and the segments bench/tick_path.py
computes from them, on a tick whose every time is known."""

from __future__ import annotations

import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from reconswarm.net.runtime import trace
from reconswarm.net.runtime.trace import Mark

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
import tick_path


def _events(rows: list[tuple[Mark, int, int, float]]) -> dict[tuple[str, int], dict[int, float]]:
    out: dict[tuple[str, int], dict[int, float]] = {}
    for what, k, agent, t in rows:
        out.setdefault((what.value, k), {}).setdefault(agent, t)
    return out


@pytest.fixture
def tracing(tmp_path: Path) -> Iterator[Path]:
    trace.start(str(tmp_path))
    yield tmp_path
    trace.start(None)


def test_marks_are_kept_only_while_tracing_and_written_as_rows(tracing: Path) -> None:
    trace.mark(Mark.CLOCK_PUT, 7, 0, 1.5)
    trace.mark(Mark.CMD_IN, 7, 3, 1.25)
    path = trace.write()
    assert path is not None and path.parent == tracing
    assert path.read_text().splitlines() == ["clock_put\t7\t0\t1.5000000", "cmd_in\t7\t3\t1.2500000"]
    assert tick_path.read(tracing)[int(path.stem)] == {("clock_put", 7): {0: 1.5}, ("cmd_in", 7): {3: 1.25}}
    trace.start(None)
    trace.mark(Mark.CLOCK_PUT, 8, 0, 2.0)
    assert trace.write(str(tracing)) is None  # (nothing kept: tracing is off)


def test_a_trace_that_cannot_be_written_says_so_in_one_line(tracing: Path, capsys: pytest.CaptureFixture[str]) -> None:
    trace.mark(Mark.CLOCK_PUT, 1, 0, 1.0)
    assert trace.write(str(tracing / "missing")) is None
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(f"{trace.ENV}={tracing / 'missing'}: cannot write the trace: ")


def test_a_mark_without_a_time_is_stamped_with_the_monotonic_clock(tracing: Path) -> None:
    before = time.monotonic()
    trace.mark(Mark.STATE_PUT, 1, 2)
    after = time.monotonic()
    path = trace.write()
    assert path is not None
    t = float(path.read_text().split("\t")[3])
    assert before - 1e-6 <= t <= after + 1e-6


def test_segments_of_a_tick_with_two_hosts() -> None:
    # The world: clock of tick 5 at 10.000 s, states of agents 1-4 put by 10.001, commands in, the next clock.
    world = _events([(Mark.CLOCK_PUT, 5, 0, 10.000), (Mark.STATE_PUT, 5, 1, 10.0005), (Mark.STATE_PUT, 5, 2, 10.0006),
                     (Mark.STATE_PUT, 5, 3, 10.0008), (Mark.STATE_PUT, 5, 4, 10.001),
                     (Mark.CMD_IN, 5, 1, 10.0040), (Mark.CMD_IN, 5, 2, 10.0041), (Mark.CMD_IN, 5, 3, 10.0045),
                     (Mark.CMD_IN, 5, 4, 10.0046), (Mark.CLOCK_PUT, 6, 0, 10.0052)])
    host_a = _events([(Mark.STATE_IN, 5, 1, 10.0009), (Mark.STATE_IN, 5, 2, 10.0010),  # hop 0.0004 each
                      (Mark.BEACON_PUT, 5, 1, 10.0013), (Mark.BEACON_PUT, 5, 2, 10.0015),
                      (Mark.BEACON_IN, 5, 3, 10.0020), (Mark.BEACON_IN, 5, 4, 10.0022),
                      (Mark.CMD_PUT, 5, 1, 10.0030), (Mark.CMD_PUT, 5, 2, 10.0031)])
    host_b = _events([(Mark.STATE_IN, 5, 3, 10.0010), (Mark.STATE_IN, 5, 4, 10.0014),  # hop 0.0002, 0.0004
                      (Mark.BEACON_PUT, 5, 3, 10.0016), (Mark.BEACON_PUT, 5, 4, 10.0017),
                      (Mark.BEACON_IN, 5, 1, 10.0016), (Mark.BEACON_IN, 5, 2, 10.0019),  # in before its own last
                      (Mark.CMD_PUT, 5, 3, 10.0040), (Mark.CMD_PUT, 5, 4, 10.0044)])
    seg = tick_path.segments(world, {1: host_a, 2: host_b}, range(0, 10))
    got = {name: [round(x * 1e4, 6) for x in xs] for name, xs in seg.items()}  # (in tenths of a millisecond)
    assert got == {
        "world_puts": [10.0],
        "state_hop": [4.0, 3.0],  # (b: the median of 2 and 4)
        "to_beacons": [5.0, 3.0],
        "beacon_wait": [7.0, 2.0],
        "to_commands": [9.0, 25.0],  # (b: from the other's last beacon, the later)
        "command_hop": [10.0, 3.5],
        "world_step": [6.0],
        "tick": [52.0],
        "beacon_hop": [4.5, 3.5],
    }


def test_a_host_alone_waits_for_no_other_process_and_a_tick_without_marks_is_left_out() -> None:
    world = _events([(Mark.CLOCK_PUT, 1, 0, 1.0), (Mark.STATE_PUT, 1, 1, 1.001), (Mark.CMD_IN, 1, 1, 1.004)])
    host = _events([(Mark.STATE_IN, 1, 1, 1.002), (Mark.BEACON_PUT, 1, 1, 1.0025), (Mark.CMD_PUT, 1, 1, 1.003)])
    seg = tick_path.segments(world, {9: host}, range(0, 3))
    assert seg["beacon_wait"] == []
    assert [round(x, 9) for x in seg["to_commands"]] == [0.0005]
    assert seg["tick"] == [] and seg["world_step"] == []
    assert [round(x, 9) for x in seg["world_puts"]] == [0.001]  # (tick 1 only)
