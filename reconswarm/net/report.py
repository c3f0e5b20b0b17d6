"""Intrusion reports: each process's tally of refused messages, sent to the monitor for the run record.

Key `swarm/<run>/report/<process>` (`simworld`, `agent-<id>`); payload `{v, process, rows: [[kind, source,
count, first_t], ...]}`, the whole tally each time (at most `MAX_ROWS` rows), sent at most once a second
and only when it changed. The monitor admits a report only from the session that speaks for that process.
"""

from __future__ import annotations

from dataclasses import dataclass

from reconswarm.net.wire import WireError, _int, _num, _pack, _str, _unpack

MAX_ROWS = 300
Row = tuple[str, str, int, float]  # kind, source, count, first_t


@dataclass(frozen=True)
class Report:
    process: str
    rows: tuple[Row, ...]


def report_to_wire(m: Report) -> bytes:
    return _pack({"process": m.process, "rows": [list(r) for r in m.rows[:MAX_ROWS]]})


def report_from_wire(payload: bytes, process: str | None = None) -> Report:
    """Decode; `process` (from the key) must match the payload's."""
    o = _unpack(payload)
    proc = _str(o.get("process"), "field 'process'")
    if process is not None and proc != process:
        raise WireError(f"field 'process': {proc!r} on the key of {process!r}")
    raw = o.get("rows")
    if not isinstance(raw, list) or len(raw) > MAX_ROWS:
        raise WireError(f"field 'rows': expected a list of at most {MAX_ROWS} rows")
    rows: list[Row] = []
    for r in raw:
        if not isinstance(r, list) or len(r) != 4:
            raise WireError("field 'rows': each row is [kind, source, count, first_t]")
        rows.append((_str(r[0], "row kind"), _str(r[1], "row source"), _int({"n": r[2]}, "n"),
                     _num(r[3], "row first_t")))
    return Report(proc, tuple(rows))
