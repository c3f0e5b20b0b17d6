"""The cells an agent host listens to, and for which of its agents: the session's cell subscriptions.

Each hosted agent listens to the cells around it (agent/neighbours.py `Cells`: a set of cells, or every cell until
its first command). The host declares, per cell at least one of its running agents listens to, one subscription to
the peer hosts' beacon batches and one advanced subscription to the obstacle sets published there (with history:
the publishers' cached sets), both for remote samples only (co-hosted agents hear each other in the process:
agent/loopback.py). Cells new to the host are declared before the ones nobody listens to any more go; while an
agent listens to every cell, the cells around the hosted agents' starts (`warm`) are declared as well, so that its
own cells are declared already when it first commands (not all at once, on the mission's first tick).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import zenoh
from zenoh import ext

from reconswarm.net.runtime.inbox import Inbox
from reconswarm.net.wire.cells import Cell
from reconswarm.net.wire.keys import Keys, WireError

Listen = frozenset[Cell] | None  # the cells an agent listens to (None: every cell)


class CellListening:
    """Who of the hosted agents listens to which cell, and the host's subscriptions that follow from it."""

    def __init__(self, session: zenoh.Session, keys: Keys, inbox: Inbox, warm: frozenset[Cell],
                 active: Mapping[int, Any]) -> None:
        self.z, self.keys, self.inbox, self.warm = session, keys, inbox, warm
        self.active = active  # the hosted agents still running (the host's: one that exits leaves it)
        self.locality = zenoh.Locality.REMOTE  # (co-hosted agents' samples are handed over in the process)
        self.listening: dict[int, Listen] = {}  # agent -> the cells it listens to (None: all)
        self.by_cell: dict[Cell | None, set[int]] = {}  # cell -> the agents listening to it (None: to all)
        self._heard_by: dict[Cell | None, list[int]] = {}  # cell -> `listeners` (until listening or `active` change)
        self.subs: dict[Cell | None, tuple[Any, Any]] = {}  # the host's subscriptions (None: every cell)

    def listen(self, aid: int, listen: Listen) -> Callable[[str], bool] | None:
        """Agent aid listens to `listen` from now on. None if nothing changed; else whether a key's cell is one it
        hears now and did not before."""
        old = self.listening.get(aid, frozenset())
        if aid in self.listening and old == listen:
            return None
        self.listening[aid] = listen
        self._heard_by.clear()
        for cell in {None} if old is None else old:
            self.by_cell.get(cell, set()).discard(aid)
        for cell in {None} if listen is None else listen:
            self.by_cell.setdefault(cell, set()).add(aid)
        self._declare()
        return lambda key: self._hears(listen, cell := self.cell_of(key)) and not self._hears(old, cell)

    def forget(self, aid: int) -> None:
        """Agent aid stopped: it listens to nothing, and is no listener any more."""
        self.listen(aid, frozenset())
        self.listening.pop(aid)

    def changed(self) -> None:
        """The running agents changed (one exited): who listens to a cell is asked again."""
        self._heard_by.clear()

    def _declare(self) -> None:
        want: set[Cell | None] = {cell for cell, heard_by in self.by_cell.items() if heard_by}  # (every listened cell)
        if None in want:
            want |= self.warm
        for cell in want - self.subs.keys():
            tag, k = ("cell", cell), self.keys
            self.subs[cell] = (
                self.z.declare_subscriber(k.host_beacons(cell, None), self.inbox.handler(tag, rows=True),
                                          allowed_origin=self.locality),
                ext.declare_advanced_subscriber(self.z, k.cell_agents(cell, "obstacles"), self.inbox.handler(tag),
                                                allowed_origin=self.locality,
                                                history=ext.HistoryConfig(detect_late_publishers=True)))
        for cell in self.subs.keys() - want:
            for sub in self.subs.pop(cell):
                sub.undeclare()

    def listeners(self, cell: Cell | None) -> list[int]:
        """The running agents that listen to `cell` (a valid one; None: nobody but those listening to every cell),
        in id order."""
        heard_by = self._heard_by.get(cell)
        if heard_by is None:
            got = self.by_cell.get(cell, set()) if cell is not None else set()
            heard_by = self._heard_by[cell] = sorted(a for a in got | self.by_cell.get(None, set()) if a in self.active)
        return heard_by

    @staticmethod
    def _hears(listen: Listen, cell: Cell | None) -> bool:
        return listen is None or cell in listen

    def cell_of(self, key: str) -> Cell | None:
        """The cell a beacon batch or obstacle set was published in (None: a key without a valid one)."""
        try:
            return self.keys.parsed(key).cell
        except WireError:
            return None

    def close(self) -> None:
        for subs in self.subs.values():
            for sub in subs:
                sub.undeclare()
        self.subs.clear()
