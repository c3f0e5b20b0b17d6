"""The link rule, the one definition of "linked" (docs/paper.md): two agents are linked when
their head points are within the link range. Pure.

Knowledge sharing uses the rule as it stands: an agent merges the sets of the agents linked to it at this
tick. The swarm graph (topology) adds hysteresis so that an edge does not flicker: a pair linked at the
previous tick stays linked up to link range + HYSTERESIS_M.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

HYSTERESIS_M = 2.0

Array = NDArray[np.float64]


def linked(d: Array, link_m: float, was_linked: NDArray[np.bool_] | None = None,
           hysteresis_m: float = HYSTERESIS_M) -> NDArray[np.bool_]:
    """Which pairs at head-point distances d (E,) are linked: d <= link_m, or, for pairs linked at the
    previous tick (was_linked (E,), the swarm graph's hysteresis), d <= link_m + hysteresis_m. -> (E,)"""
    now = d <= link_m
    if was_linked is None:
        return now
    return now | (was_linked & (d <= link_m + hysteresis_m))
