"""`reconswarm sweep --plot`: one column of panels per suite (scenario directory), from results.csv."""

from __future__ import annotations

from pathlib import Path

import pytest

from reconswarm.errors import BadInput
from reconswarm_bringup.sweep import COLUMNS
from reconswarm_bringup.sweep_plot import plot, suite_of


def test_suites_are_the_scenario_directories_and_the_png_is_written(tmp_path: Path) -> None:
    rows = [("deploy/scenarios/paper.toml", "reconfigurable", "True", "222.25", "0"),
            ("gen/n10-s0.toml", "orca", "True", "90.5", "0"), ("gen/n10-s1.toml", "orca", "False", "", "3"),
            ("gen/n20-s0.toml", "hl", "True", "101.0", "2")]
    csv = tmp_path / "results.csv"
    lines = [",".join(COLUMNS)]
    for scen, kind, conv, t, coll in rows:
        row = dict.fromkeys(COLUMNS, "0")
        row.update(scenario=scen, planner=kind, converged=conv, convergence_time_s=t, collisions=coll)
        lines.append(",".join(row[c] for c in COLUMNS))
    csv.write_text("\n".join(lines) + "\n")
    png = tmp_path / "fig" / "planners.png"
    assert plot(csv, png) == 2
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (suite_of("deploy/scenarios/paper.toml"), suite_of("gen/a.toml"), suite_of("b.toml")) == \
        ("scenarios", "gen", "b")


def test_an_empty_results_file_is_one_line(tmp_path: Path) -> None:
    csv = tmp_path / "results.csv"
    csv.write_text(",".join(COLUMNS) + "\n")
    with pytest.raises(BadInput, match="holds no run to plot"):
        plot(csv, tmp_path / "x.png")
