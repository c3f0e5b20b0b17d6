"""What the run calls an event: one typed record, the same object written to run.db and published on
`swarm/<run>/event` (so the record and the wire cannot disagree).

Kinds: the swarm graph splitting or merging (the paper's topology events, or a network cut seen as
several agents vanishing together, `cause = "network"`), an agent lost or joined (its liveliness token),
and the world (simworld) stalling or being lost.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Any

Groups = tuple[tuple[int, ...], ...]


class EventKind(StrEnum):
    SPLIT = "split"
    MERGE = "merge"
    AGENT_LOST = "agent_lost"
    AGENT_JOINED = "agent_joined"
    WORLD_STALLED = "world_stalled"  # the world's clock stopped and came back (t .. t + duration_s)
    WORLD_LOST = "world_lost"  # the world's clock stopped for good: the mission ended without it


MEMBERSHIP = (EventKind.AGENT_LOST, EventKind.AGENT_JOINED)
_OPTIONAL = ("agent", "cause", "t_confirmed", "duration_s", "wall_unix")


@dataclass(frozen=True)
class Event:
    """t: simulated time the change began; before/after: the groups (agent ids) it changed;
    agent: the agent of a membership event; cause: "network" for a split or merge seen as lost tokens;
    t_confirmed: when a topology change had persisted long enough; duration_s: a world stall's wall
    seconds; wall_unix: when the monitor noticed (fault-detection latency)."""

    t: float
    kind: EventKind
    before: Groups = ()
    after: Groups = ()
    agent: int | None = None
    cause: str | None = None
    t_confirmed: float | None = None
    duration_s: float | None = None
    wall_unix: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """The documented schema: t, kind, before, after, then each optional field that is set."""
        out: dict[str, Any] = {"t": self.t, "kind": self.kind.value, "before": [list(g) for g in self.before],
                               "after": [list(g) for g in self.after]}
        for key in _OPTIONAL:
            v = getattr(self, key)
            if v is not None:
                out[key] = v
        return out

    @staticmethod
    def from_dict(d: dict[str, Any]) -> Event:
        """From to_dict()'s shape (and the topology tracker's dicts); KeyError / ValueError when malformed."""
        unknown = set(d) - {"t", "kind", "before", "after", *_OPTIONAL}
        if unknown:
            raise ValueError(f"unknown event field(s) {', '.join(sorted(unknown))}")
        return Event(float(d["t"]), EventKind(d["kind"]), _groups(d.get("before", ())), _groups(d.get("after", ())),
                     None if d.get("agent") is None else int(d["agent"]),
                     None if d.get("cause") is None else str(d["cause"]),
                     *(None if d.get(k) is None else float(d[k]) for k in ("t_confirmed", "duration_s", "wall_unix")))


def _groups(g: Any) -> Groups:
    return tuple(tuple(int(a) for a in grp) for grp in g)
