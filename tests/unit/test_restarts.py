"""The launcher's restart policy (reconswarm_bringup/restarts.py): five restarts, then the sixth death is fatal.

Every router and monitor system test kills its process once; these count every death up to the limit."""

from __future__ import annotations

from reconswarm_bringup.restarts import MONITOR_DELAYS_S, ROUTER_DELAYS_S, Restarts


def deaths(policy: Restarts, n: int) -> list[float | None]:
    return [policy.after_death() for _ in range(n)]


def test_the_router_is_restarted_five_times_at_once_then_backing_off_and_its_sixth_death_is_fatal() -> None:
    router = Restarts(ROUTER_DELAYS_S)
    assert deaths(router, 7) == [0.0, 0.5, 1.0, 2.0, 4.0, None, None]
    assert router.done == router.limit == 5


def test_the_monitor_is_restarted_five_times_backing_off_and_its_sixth_death_is_fatal() -> None:
    monitor = Restarts(MONITOR_DELAYS_S)
    assert deaths(monitor, 6) == [0.5, 1.0, 2.0, 4.0, 8.0, None]
    assert monitor.done == 5


def test_each_role_counts_its_own_deaths() -> None:
    router, monitor = Restarts(ROUTER_DELAYS_S), Restarts(MONITOR_DELAYS_S)
    deaths(router, 5)
    assert monitor.after_death() == 0.5 and router.after_death() is None
