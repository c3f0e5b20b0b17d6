"""The launcher's view of the run's clock: progress, fault timing, and whether the world ended the mission.

A clock counts only from the world's session (`Admission.check_clock`), but a session id can be stamped by
anyone on the run's router (open mode): a forged `end` carrying the world's id passes that check. So, as the
monitor does (monitor/node.py), a claimed end is only tentative here: any clock of the world after it refutes
it (the world puts nothing after its own end; a forged end may claim any tick), and faults due later still fire.
"""

from __future__ import annotations

import contextlib
import logging
from dataclasses import dataclass

import zenoh

from reconswarm.net.runtime.inbox import sample_source
from reconswarm.net.runtime.session import ZenohOptions, open_session
from reconswarm.net.trust.admission import Admission
from reconswarm.net.wire import wire
from reconswarm.net.wire.keys import Keys, WireError
from reconswarm.scenario.model import Scenario

log = logging.getLogger("reconswarm.launch")
CLOCK_RING = 64  # clocks kept between two polls (the launcher polls every 50 ms): a forged one cannot hide the world's


@dataclass
class ClockFollow:
    """What the admitted clocks say so far (pure: fed one admitted clock at a time)."""

    t: float = 0.0
    k: int = -1
    alive: int = 0
    end: wire.Clock | None = None  # the end claimed, until a later clock of the world refutes it
    refuted: int = 0  # ends refuted so far (forged: the world ticked on after them)

    def take(self, c: wire.Clock) -> None:
        if c.end:
            if self.end is None:
                self.end = c
            return
        if self.end is not None:  # the world ticks on: it did not end (it puts nothing after its own end)
            log.warning("a claimed end of the mission (tick %d, %r) was not the world's: its clock went on at tick %d",
                        self.end.k, self.end.reason, c.k)
            self.refuted += 1
            self.end = None
        if c.k >= self.k:
            self.t, self.k, self.alive = c.t, c.k, len(c.alive)


class ClockWatch:
    """Follows the run's clock on its own zenoh session. Clocks land in a ring (the newest CLOCK_RING), read when
    the launcher polls, so this process does not wake for every tick."""

    def __init__(self, run: str, zopts: ZenohOptions, s: Scenario) -> None:
        self.keys = Keys(run)
        self.admission = Admission(s)  # a clock counts only from the world's session
        self.session = open_session(zopts, "run_local")
        self.clock_sub = self.session.declare_subscriber(self.keys.clock, zenoh.handlers.RingChannel(CLOCK_RING))
        self.follow = ClockFollow()

    @property
    def t(self) -> float:
        return self.follow.t

    @property
    def k(self) -> int:
        return self.follow.k

    @property
    def alive(self) -> int:
        return self.follow.alive

    @property
    def end(self) -> wire.Clock | None:
        return self.follow.end

    def poll(self) -> None:
        while (sample := self.clock_sub.try_recv()) is not None:
            with contextlib.suppress(WireError):
                c = wire.clock_from_wire(sample.payload.to_bytes())
                if self.admission.check_clock(c, sample_source(sample), self.keys.clock) is None:
                    self.follow.take(c)

    def close(self) -> None:
        self.session.close()
