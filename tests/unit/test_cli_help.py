"""Help that does not confuse, and real time that means 1x (issue 21, frictions 6 and 7).

- Every command's help: a switch shows no value (`--secure`, not `--secure <bool>`), an argument is named
  in capitals (`RUN.DB`, `SCENARIO...`), never `{db}` or `<list[Path]>`; `monitor record` says it hears
  reports, not beacons.
- `--clock realtime` (and `--ros2`) without `--speed` run at 1x: the launcher's configuration, the
  simworld command's, and the world node's own default period (one tick per dt of wall time).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from reconswarm.scenario.generate import generate
from reconswarm.scenario.model import to_toml
from reconswarm_bringup.cli import app

COMMANDS = [(), ("sim",), ("sweep",), ("launch",), ("scenario",), ("scenario", "generate"), ("scenario", "check"),
            ("monitor",), ("monitor", "summary"), ("monitor", "events"), ("monitor", "export"), ("monitor", "plot"),
            ("monitor", "animate"), ("monitor", "record"), ("agent",), ("simworld",), ("router",)]
WIDE = {"COLUMNS": "200", "TERMINAL_WIDTH": "200", "NO_COLOR": "1"}


def _help(*cmd: str) -> str:
    r = CliRunner().invoke(app, [*cmd, "--help"], env=WIDE)
    assert r.exit_code == 0, r.output
    return r.output


@pytest.mark.parametrize("cmd", COMMANDS, ids=lambda c: " ".join(c) or "reconswarm")
def test_help_shows_switches_without_a_value_and_arguments_by_name(cmd: tuple[str, ...]) -> None:
    text = _help(*cmd)
    assert "<bool>" not in text
    assert not re.search(r"\{\w+\}", text), text  # {db}
    assert "list[" not in text and "<list" not in text
    help_line = next(ln for ln in text.splitlines() if "--help" in ln)
    assert re.search(r"--help\s+Show this message", help_line), help_line


def test_the_switches_of_launch_take_no_value() -> None:
    text = _help("launch")
    for switch in ("--secure", "--ros2", "--json", "--no-progress", "--debug"):
        (line,) = [ln for ln in text.splitlines() if re.search(rf"{switch}\s", ln)]
        after = line.split(switch, 1)[1].strip(" │")
        assert not after.startswith("<"), line
    assert re.search(r"--agents\s+-n\s+<int>", text)  # an option with a value still shows its type


def test_arguments_are_named_in_capitals() -> None:
    assert re.search(r"Usage: .*monitor summary \[OPTIONS\] RUN\.DB", _help("monitor", "summary"))
    assert re.search(r"Usage: .*sweep \[OPTIONS\] SCENARIO\.\.\.", _help("sweep"))
    assert re.search(r"Usage: .*sim \[OPTIONS\] SCENARIO\b", _help("sim"))


def test_monitor_record_says_what_it_hears() -> None:
    text = " ".join(_help("monitor", "record").split())
    assert "reports" in text and "does not hear the agents' beacons" in text


@pytest.fixture
def tiny(tmp_path: Path) -> Path:
    p = tmp_path / "g.toml"
    p.write_text(to_toml(generate(3, 1, 1)))
    return p


@pytest.mark.parametrize("args", [("--clock", "realtime"), ("--ros2",)])
def test_realtime_defaults_to_real_time(tmp_path: Path, tiny: Path, monkeypatch: pytest.MonkeyPatch,
                                        args: tuple[str, ...]) -> None:
    from reconswarm_bringup import launcher

    seen: list[Any] = []
    def fake_run(cfg: Any) -> int:
        seen.append(cfg)
        return 0

    monkeypatch.setattr(launcher, "run", fake_run)
    r = CliRunner().invoke(app, ["launch", "-s", str(tiny), "-o", str(tmp_path / "out"), *args])
    assert r.exit_code == 0, r.output
    (cfg,) = seen
    assert cfg.clock == "realtime" and cfg.speed == 1.0


def test_simworld_command_defaults_to_real_time(tiny: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import simworld.process

    seen: list[Any] = []
    def fake_run(cfg: Any) -> int:
        seen.append(cfg)
        return 0

    monkeypatch.setattr(simworld.process, "run", fake_run)
    r = CliRunner().invoke(app, ["simworld", "--scenario", str(tiny), "--clock", "realtime",
                                 "--connect", "tcp/127.0.0.1:9"])
    assert r.exit_code == 0, r.output
    (cfg,) = seen
    assert cfg.speed == 1.0


def test_world_node_defaults_to_real_time(tiny: Path) -> None:
    from reconswarm.net.wire.wire import ClockMode
    from reconswarm.scenario.model import load
    from simworld.world import WorldNode

    s = load(tiny)
    assert WorldNode(s, ClockMode.REALTIME).speed == 1.0
