"""The planners by name (the scenario's `planner.kind`): name -> "module:factory", imported when first made,
so an optional dependency is needed only by the planner that uses it. A factory takes (scenario, row ids)."""

from __future__ import annotations

import importlib
from collections.abc import Sequence

from reconswarm.planners.seam import Planner
from reconswarm.scenario.model import Scenario

REGISTRY: dict[str, str] = {
    "reconfigurable": "reconswarm.planners.paper_law:PaperLaw",
    "virtual-leader": "reconswarm.planners.paper_law:PaperLaw",
    "orca": "reconswarm.planners.navground_behaviors:orca",
    "hrvo": "reconswarm.planners.navground_behaviors:hrvo",
    "hl": "reconswarm.planners.navground_behaviors:hl",
    "social-force": "reconswarm.planners.navground_behaviors:social_force",
}


def make(s: Scenario, ids: Sequence[int] | None = None) -> Planner:
    """The scenario's planner for the agents `ids` (its rows, in this order; None: every agent).
    BadInput (one line) if the planner needs a dependency that is not installed."""
    module, factory = REGISTRY[s.planner.kind.value].split(":")
    planner: Planner = getattr(importlib.import_module(module), factory)(s, ids)
    return planner


def require(s: Scenario) -> None:
    """Fail early (BadInput) if the scenario's planner cannot be made here: one row, thrown away."""
    make(s, [s.agents[0].id])
