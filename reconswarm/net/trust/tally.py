"""The tally of intrusions a process refused: counts per (kind, source), with the first time each was seen."""

from __future__ import annotations

from dataclasses import dataclass, field

from reconswarm.net.trust.admission import Intrusion


@dataclass
class IntrusionTally:
    """Counts per (kind, source), with the first time each was seen; `add` says whether to log it."""

    rows: dict[tuple[str, str], list[float]] = field(default_factory=dict)  # -> [count, first_t]
    max_rows: int = 256
    total: int = 0  # every intrusion counted (the rows' counts summed)

    def add(self, i: Intrusion, t: float) -> bool:
        self.total += 1
        k = (i.kind.value, i.source)
        row = self.rows.get(k)
        if row is None:
            if len(self.rows) >= self.max_rows:  # an attacker cycling session ids: fold the rest into one row
                k = (i.kind.value, "(other sources)")
                row = self.rows.setdefault(k, [0, t])
            else:
                row = self.rows[k] = [0, t]
        row[0] += 1
        return row[0] == 1

    def as_rows(self) -> list[tuple[str, str, int, float]]:
        """(kind, source, count, first_t), as the run record stores them."""
        return [(k, s, int(r[0]), float(r[1])) for (k, s), r in sorted(self.rows.items())]
