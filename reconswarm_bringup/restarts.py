"""How often the launcher restarts a process that died, and after how long: a count and its delays, no processes.

The launcher (reconswarm_bringup/launcher.py) keeps one `Restarts` per role it restarts (the monitor, the
router): each death asks `after_death()` for the delay of the next restart; `None` means this death is one more
than the limit, and the run fails.
"""

from __future__ import annotations

from dataclasses import dataclass

# The monitor: restarted after 0.5, 1, 2, 4, 8 s; its sixth death fails the run.
MONITOR_DELAYS_S = (0.5, 1.0, 2.0, 4.0, 8.0)
# The router: restarted at once, then after 0.5, 1, 2, 4 s; its sixth death fails the run.
ROUTER_DELAYS_S = (0.0, 0.5, 1.0, 2.0, 4.0)


@dataclass
class Restarts:
    """The restarts of one role so far (`done`) against its delays (one per restart allowed)."""

    delays_s: tuple[float, ...]
    done: int = 0

    @property
    def limit(self) -> int:
        """Restarts allowed: a death beyond this many restarts is fatal."""
        return len(self.delays_s)

    def after_death(self) -> float | None:
        """Count one more death: the delay before its restart, or None when the limit is used up."""
        if self.done >= self.limit:
            return None
        delay = self.delays_s[self.done]
        self.done += 1
        return delay
