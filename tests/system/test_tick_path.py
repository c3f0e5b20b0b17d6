"""The tick's serial path traced in a real run (RECONSWARM_TRACE_DIR; bench/tick_path.py reads it): every process
marks its puts and arrivals, each host only its own agents', and every segment is measured on (nearly) every tick,
a sample never arriving before it was put (one monotonic clock for the machine's processes)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from reconswarm.net.runtime.trace import ENV, Mark
from tests.support import PAPER, ROOT, launcher_cmd, scenario_with

sys.path.insert(0, str(ROOT / "bench"))
import tick_path


def test_a_traced_run_gives_every_segment_of_the_tick(tmp_path: Path) -> None:
    scen = scenario_with(tmp_path, "short.toml", PAPER.read_text(), **{"duration_s = 300.0": "duration_s = 5.0"})
    trace_dir = tmp_path / "trace"
    trace_dir.mkdir()
    p = subprocess.run(launcher_cmd(tmp_path / "run", "-s", str(scen), "--agents-per-process", "5", "--json"),
                       capture_output=True, text=True, timeout=300, cwd=ROOT, env={**os.environ, ENV: str(trace_dir)})
    assert p.returncode == 1, p.stderr  # (not converged in 5 s)
    ticks = json.loads(p.stdout)["ticks"]
    assert ticks == 101
    marks = tick_path.read(trace_dir)
    worlds, hosts = tick_path.roles(marks)
    assert len(worlds) == 1 and len(hosts) == 2
    world = worlds[0]
    assert all((Mark.CLOCK_PUT.value, k) in world for k in range(ticks))
    # Each host marks its own five agents' states, beacons and commands, and the other five's beacons.
    own = sorted(sorted(ev[(Mark.STATE_IN.value, 10)]) for ev in hosts.values())
    assert own == [[1, 2, 3, 4, 5], [6, 7, 8, 9, 10]]
    for ev in hosts.values():
        mine = sorted(ev[(Mark.STATE_IN.value, 10)])
        assert sorted(ev[(Mark.BEACON_PUT.value, 10)]) == mine and sorted(ev[(Mark.CMD_PUT.value, 10)]) == mine
        assert sorted(ev[(Mark.BEACON_IN.value, 10)]) == sorted(set(range(1, 11)) - set(mine))
    seg = tick_path.segments(world, hosts, range(1, ticks - 1))
    may_be_negative = "to_commands"  # (an agent none of the late beacons mattered to)
    for key in tick_path.SEGMENTS:
        per_host = 1 if key in ("world_puts", "world_step", "tick") else 2
        assert len(seg[key]) >= 0.9 * per_host * (ticks - 2), (key, len(seg[key]))
        # Causality: nothing arrives before it was put (one clock), no step ends before the input it needs.
        assert key == may_be_negative or min(seg[key]) >= 0.0, (key, min(seg[key]))
    tick = sorted(seg["tick"])
    assert 0 < tick[len(tick) // 2] < 1.0
