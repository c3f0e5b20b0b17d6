"""Reports: each process's telemetry for the monitor, off the control messages.

Key `swarm/<run>/report/<process>` (`simworld`, `agent-<id>`); payload `{v, process, rows?, rejected,
guessed_k}`:
- `rows: [[kind, source, count, first_t], ...]`: the process's whole tally of refused messages (at most
  `MAX_ROWS` rows), present only when it changed (at most once a second);
- `rejected`: the messages it dropped as malformed so far; `guessed_k`: lockstep, the first tick it acted
  on without all its data (-1: none).
An agent reports every `Timing.telemetry_s` of wall time (its heartbeat: the monitor counts an agent alive
while its token is there and its reports keep coming), and at once when `guessed_k` is first set; the
world reports only a changed tally (its `rejected` rides on its clock). The monitor admits a report only
from the session that speaks for that process.
"""

from __future__ import annotations

from dataclasses import dataclass

from reconswarm.net.wire.keys import WireError
from reconswarm.net.wire.wire import _int, _num, _pack, _str, _unpack
from reconswarm.scenario.wire_limits import agent_id_from_text

MAX_ROWS = 300
Row = tuple[str, str, int, float]  # kind, source, count, first_t


@dataclass(frozen=True)
class Report:
    process: str
    rows: tuple[Row, ...] | None  # None: the tally did not change since the last report
    rejected: int = 0
    guessed_k: int = -1

    @property
    def agent_id(self) -> int | None:
        """Whose report: an agent's id, None for the world's; WireError for another name (the key's parse, which
        the name matches, refuses it first)."""
        if self.process == "simworld":
            return None
        aid = agent_id_from_text(self.process[6:]) if self.process.startswith("agent-") else None
        if aid is None:
            raise WireError(f"field 'process': {self.process!r} is no process of a run")
        return aid


def report_to_wire(m: Report) -> bytes:
    d: dict[str, object] = {"process": m.process, "rejected": m.rejected, "guessed_k": m.guessed_k}
    if m.rows is not None:
        d["rows"] = [list(r) for r in m.rows[:MAX_ROWS]]
    return _pack(d)


def report_from_wire(payload: bytes, process: str | None = None) -> Report:
    """Decode; `process` (from the key) must match the payload's."""
    o = _unpack(payload)
    proc = _str(o.get("process"), "field 'process'")
    if process is not None and proc != process:
        raise WireError(f"field 'process': {proc!r} on the key of {process!r}")
    rejected, guessed_k = _int(o, "rejected", 0, 2**53, 0), _int(o, "guessed_k", -1, 2**53, -1)
    raw = o.get("rows")
    if raw is None:
        return Report(proc, None, rejected, guessed_k)
    if not isinstance(raw, list) or len(raw) > MAX_ROWS:
        raise WireError(f"field 'rows': expected a list of at most {MAX_ROWS} rows")
    rows: list[Row] = []
    for r in raw:
        if not isinstance(r, list) or len(r) != 4:
            raise WireError("field 'rows': each row is [kind, source, count, first_t]")
        rows.append((_str(r[0], "row kind"), _str(r[1], "row source"), _int({"n": r[2]}, "n"),
                     _num(r[3], "row first_t")))
    return Report(proc, tuple(rows), rejected, guessed_k)
