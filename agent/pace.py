"""What a pace (agent/lockstep.py, agent/realtime.py) reads and does of an agent's node (agent/node.py's AgentNode):
the node keeps what it heard and its tick; the pace decides when a tick is acted on and with which peers and sets."""

from __future__ import annotations

from collections.abc import Set as AbstractSet
from typing import Protocol

import numpy as np

from agent.brain import AgentBrain
from agent.heard import Heard
from agent.messages import Output
from agent.neighbours import Neighbourhood
from agent.sets import ObstacleSets, PeerSets
from reconswarm.net.timing import Timing
from reconswarm.net.trust.membership import Policy
from reconswarm.net.wire import wire


class Paced(Protocol):
    """An agent node as its pace sees it."""

    timing: Timing
    policy: Policy
    h: Heard
    nb: Neighbourhood
    brain: AgentBrain
    peer_sets: PeerSets
    sets: dict[int, dict[int, ObstacleSets]]
    merged: dict[int, int]
    merged_union: dict[int, int]
    out: list[Output]
    k: int  # the last tick commanded
    planning: int  # the tick of our plan out (-1: none)
    now: float
    period_s: float
    act_at: float | None
    beacon_sent: int
    beacon_again: float
    again_n: int
    wait_since: float | None
    guess: str
    link_lost: bool
    linked: tuple[int, dict[int, int]]
    waited: dict[tuple[int, int, bool], tuple[wire.Clock | None, frozenset[int]]]
    started: bool
    ended: bool
    world_gone: bool
    world_at: float

    def act(self, k: int, now: float) -> None: ...
    def move(self, k: int, st: wire.State) -> None: ...
    def beacon(self, st: wire.State) -> wire.Beacon: ...
    def obstacle_set(self, k: int) -> wire.ObstacleSet: ...
    def link(self, k: int, p: np.ndarray) -> None: ...
    def quiet(self, now: float) -> bool: ...
    def expected(self, k: int, clock: wire.Clock | None) -> AbstractSet[int]: ...
