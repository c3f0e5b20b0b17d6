"""The run record `run.db` (SQLite), written as the run goes, read by every monitor command.

One schema for every mode (in-process, lockstep, realtime). Per tick one row holds the head points,
headings and liveness of all agents as float64 / uint8 blobs in agent-id order, so writing stays cheap
at thousands of agents; the writer commits at least every `commit_interval_s` of wall time (WAL mode),
so a run killed midway keeps a readable record that lacks at most that much.
"""

from __future__ import annotations

import contextlib
import json
import math
import sqlite3
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from reconswarm.errors import BadInput
from reconswarm.paper.events import Event
from reconswarm.record.safety import Episode
from reconswarm.scenario.model import Scenario, parse, to_toml

SCHEMA_VERSION = "1"
DDL = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS ticks (
    k INTEGER PRIMARY KEY, t REAL NOT NULL,
    px BLOB NOT NULL, py BLOB NOT NULL, theta BLOB NOT NULL, alive BLOB NOT NULL,
    max_error_m REAL, min_agent_gap_m REAL, min_obstacle_gap_m REAL, groups INTEGER);
CREATE TABLE IF NOT EXISTS events (seq INTEGER PRIMARY KEY AUTOINCREMENT, t REAL NOT NULL, kind TEXT NOT NULL,
    data TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS contacts (seq INTEGER PRIMARY KEY AUTOINCREMENT, kind TEXT NOT NULL, a TEXT NOT NULL,
    b TEXT NOT NULL, t_start REAL NOT NULL, t_end REAL, gap_m REAL NOT NULL);
CREATE INDEX IF NOT EXISTS contacts_open ON contacts (a, b, kind, t_end);
CREATE TABLE IF NOT EXISTS counters (process TEXT PRIMARY KEY, messages_rejected INTEGER NOT NULL);
CREATE TABLE IF NOT EXISTS gaps (t_from REAL NOT NULL, t_to REAL NOT NULL, note TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS intrusions (process TEXT NOT NULL, kind TEXT NOT NULL, source TEXT NOT NULL,
    count INTEGER NOT NULL, first_t REAL NOT NULL, PRIMARY KEY (process, kind, source));
"""

Array = NDArray[np.float64]


def _blob(a: NDArray[Any], dtype: str) -> bytes:
    return np.ascontiguousarray(a, dtype=dtype).tobytes()


_F8 = np.dtype("<f8")


def page_size(n_agents: int) -> int:
    """SQLite page size for a run of n agents. A tick row holds three blobs of 8 n bytes: beyond a hundred
    or so agents it spills over the default 4 KiB pages into chains of overflow pages, while 64 KiB pages
    hold the row of up to ~2,600 agents in one (at N = 1000, about half the CPU per row, measured)."""
    return 65536 if n_agents > 128 else 4096


class RunWriter:
    """Appends to run.db. Not thread-safe: one writer per process, called from its main loop."""

    MAX_PENDING_ROWS = 256

    def __init__(self, path: str | Path, scenario: Scenario, mode: str, *, append: bool = False,
                 commit_interval_s: float = 0.5) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if not append and self.path.exists():
            for suffix in ("", "-wal", "-shm"):
                Path(str(self.path) + suffix).unlink(missing_ok=True)
        fresh = not self.path.exists()
        self.db = sqlite3.connect(str(self.path), isolation_level=None, check_same_thread=False)
        if fresh:  # (a page size is set before the first table, and before WAL mode)
            self.db.execute(f"PRAGMA page_size={page_size(len(scenario.agents))}")
        self.db.execute("PRAGMA journal_mode=WAL")
        self.db.execute("PRAGMA synchronous=NORMAL")
        self.db.executescript(DDL)
        self.commit_interval_s = commit_interval_s
        self._rows: list[tuple[Any, ...]] = []  # tick rows not yet inserted (flushed at every commit)
        self._last_commit = time.monotonic()
        self.db.execute("BEGIN")
        existing = dict(self.db.execute("SELECT key, value FROM meta").fetchall())
        if not existing:
            self.set_meta(schema=SCHEMA_VERSION, scenario=scenario.meta.name, planner=scenario.planner.kind.value,
                          mode=mode, scenario_toml=to_toml(scenario), scenario_source=scenario.source,
                          agent_ids=json.dumps([a.id for a in scenario.agents]),
                          started_unix=f"{time.time():.3f}", finished="0")
        self.commit()

    def set_meta(self, **kv: Any) -> None:
        self.db.executemany("INSERT OR REPLACE INTO meta(key, value) VALUES (?, ?)",
                            [(k, v if isinstance(v, str) else json.dumps(v)) for k, v in kv.items()])

    def get_meta(self, key: str) -> str | None:
        row = self.db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        return None if row is None else str(row[0])

    def last_tick(self) -> tuple[int, float] | None:
        self._flush()
        row = self.db.execute("SELECT k, t FROM ticks ORDER BY k DESC LIMIT 1").fetchone()
        return (int(row[0]), float(row[1])) if row else None

    def tick(self, k: int, t: float, p: Array, theta: Array, alive: NDArray[np.bool_], max_error_m: float,
             min_agent_gap_m: float, min_obstacle_gap_m: float, groups: int) -> None:
        """p (N, 2), theta (N,), alive (N,) in agent-id order; NaN where a state is unknown."""
        if p.dtype == _F8:
            pt = p.T.copy()  # (2, N): both columns contiguous in one copy
            px, py = pt[0].tobytes(), pt[1].tobytes()
        else:
            px, py = _blob(p[:, 0], "<f8"), _blob(p[:, 1], "<f8")
        th = theta.tobytes() if theta.dtype == _F8 and theta.flags.c_contiguous else _blob(theta, "<f8")
        # Rows wait in memory until the next commit (they would not be readable before it anyway).
        self._rows.append((k, t, px, py, th, _blob(alive, "u1"), _finite(max_error_m), _finite(min_agent_gap_m),
                           _finite(min_obstacle_gap_m), groups))
        if len(self._rows) >= self.MAX_PENDING_ROWS:
            self._flush()
        self.maybe_commit()

    def _flush(self) -> None:
        if self._rows:
            self.db.executemany("INSERT OR REPLACE INTO ticks VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)", self._rows)
            self._rows = []

    def event(self, ev: Event) -> None:
        self.db.execute("INSERT INTO events(t, kind, data) VALUES (?, ?, ?)",
                        (ev.t, ev.kind.value, json.dumps(ev.to_dict())))

    def episode(self, e: Episode) -> None:
        self.db.execute("INSERT INTO contacts(kind, a, b, t_start, gap_m) VALUES (?, ?, ?, ?, ?)",
                        (e.kind, e.a, e.b, e.t_start, e.gap_m))

    def episode_end(self, key: tuple[str, str, str], t: float) -> None:
        self.db.execute("UPDATE contacts SET t_end = ? WHERE kind = ? AND a = ? AND b = ? AND t_end IS NULL",
                        (t, *key))

    def counters(self, counts: dict[str, int]) -> None:
        self.db.executemany("INSERT OR REPLACE INTO counters VALUES (?, ?)", list(counts.items()))

    def intrusions(self, process: str, rows: list[tuple[str, str, int, float]]) -> None:
        """A process's intrusion tally so far: (kind, source, count, first_t) rows, replacing earlier ones."""
        self.db.executemany("INSERT OR REPLACE INTO intrusions VALUES (?, ?, ?, ?, ?)",
                            [(process, k, s, int(n), float(t)) for k, s, n, t in rows])

    def note_gap(self, t_from: float, t_to: float, note: str) -> None:
        self.db.execute("INSERT INTO gaps VALUES (?, ?, ?)", (t_from, t_to, note))

    def maybe_commit(self) -> None:
        if time.monotonic() - self._last_commit >= self.commit_interval_s:
            self.commit()

    def commit(self) -> None:
        self._flush()
        if self.db.in_transaction:
            self.db.execute("COMMIT")
        self._last_commit = time.monotonic()
        self.db.execute("BEGIN")

    def abort(self) -> None:
        """Give up (the disk is full, say): drop what is not committed, keep what is, close."""
        self._rows = []
        try:
            if self.db.in_transaction:
                self.db.execute("ROLLBACK")
        finally:
            self.db.close()

    def close(self, **final_meta: Any) -> None:
        self._flush()
        self.set_meta(**final_meta)
        if self.db.in_transaction:
            self.db.execute("COMMIT")
        settle(self.db)
        self.db.close()


def settle(db: sqlite3.Connection) -> None:
    """A finished record is one file: the WAL checkpointed into run.db and the journal back to DELETE mode, so
    no run.db-wal / run.db-shm stays beside it and a read-only reader creates none. A record another connection
    still reads stays in WAL mode (busy: tried, not waited for; the next writer sets WAL again anyway)."""
    with contextlib.suppress(sqlite3.Error):
        db.execute("PRAGMA busy_timeout = 0")
        db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        db.execute("PRAGMA journal_mode=DELETE")


def note_stop(path: str | Path, reason: str) -> None:
    """A run ended from outside (the launcher's `stopped` on a signal, `timeout` on its --timeout): the record
    says why in its end reason and that the mission did not finish (the world, told to stop, only knows it
    was stopped). A record that does not exist (yet) or cannot be written is left as it is."""
    try:
        db = sqlite3.connect(f"{Path(path).resolve().as_uri()}?mode=rw", uri=True, isolation_level=None, timeout=5.0)
    except sqlite3.Error:
        return
    try:
        row = db.execute("SELECT value FROM meta WHERE key = 'extra'").fetchone()
        extra = json.loads(row[0]) if row is not None else {}
        extra = extra if isinstance(extra, dict) else {}
        extra["end_reason"] = reason
        db.executemany("INSERT OR REPLACE INTO meta(key, value) VALUES (?, ?)",
                       [("extra", json.dumps(extra)), ("finished", "0")])
    except (sqlite3.Error, ValueError):
        pass
    finally:
        settle(db)
        db.close()


def _finite(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


@dataclass
class Ticks:
    k: NDArray[np.int64]  # (T,)
    t: Array  # (T,)
    px: Array  # (T, N)
    py: Array  # (T, N)
    theta: Array  # (T, N)
    alive: NDArray[np.bool_]  # (T, N)
    max_error_m: Array  # (T,) NaN where not recorded
    min_agent_gap_m: Array
    min_obstacle_gap_m: Array
    groups: NDArray[np.int64]


class RunRecord:
    """Read access to a run.db (complete or still being written).

    Whatever is wrong with the file (not SQLite, pages overwritten, a table missing, a blob or a JSON
    value of the wrong shape) is a BadInput naming the file and what is wrong: reading never tracebacks.
    """

    def __init__(self, path: str | Path, scenario: Scenario | None = None) -> None:
        """scenario: the record's own, when its writer holds it (not parsed again from the record: at 100,000
        agents that takes seconds)."""
        p = Path(path)
        if not p.is_file():
            raise BadInput(f"{path}: no such run record")
        self.path = p
        try:
            self.db = sqlite3.connect(f"file:{p}?mode=ro", uri=True)
            self.meta = dict(self.db.execute("SELECT key, value FROM meta").fetchall())
        except sqlite3.Error as exc:
            if "malformed" in str(exc):  # an SQLite file whose pages are damaged
                raise self._bad(str(exc)) from None
            raise BadInput(f"{path}: not a reconswarm run record ({exc})") from None
        if "scenario_toml" not in self.meta:
            raise BadInput(f"{path}: not a reconswarm run record (meta.scenario_toml missing)")
        if not all(isinstance(v, str) for v in self.meta.values()):
            raise self._bad("meta: values must be text")
        # (a record of sim has no wire's limits)
        self.scenario = scenario if scenario is not None else parse(self.meta["scenario_toml"], str(p), wire=False)
        ids = self.meta_json("agent_ids")
        if ids != [a.id for a in self.scenario.agents]:
            raise self._bad("meta.agent_ids: not the ids of the record's scenario")
        self.ids = np.array(ids, dtype=np.int64)
        if "wall_time_s" in self.meta:
            try:
                float(self.meta["wall_time_s"])
            except ValueError:
                raise self._bad(f"meta.wall_time_s: not a number: {self.meta['wall_time_s'][:40]!r}") from None

    def _bad(self, what: str) -> BadInput:
        return BadInput(f"{self.path}: damaged run record: {what}")

    def _rows(self, sql: str, params: tuple[Any, ...] = ()) -> list[Any]:
        try:
            return self.db.execute(sql, params).fetchall()
        except sqlite3.Error as exc:  # pages overwritten ("malformed"), a table missing, ...
            raise self._bad(str(exc)) from None

    def close(self) -> None:
        self.db.close()

    def __enter__(self) -> RunRecord:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    def meta_json(self, key: str, default: Any = None) -> Any:
        if key not in self.meta:
            return default
        try:
            return json.loads(self.meta[key])
        except ValueError:
            raise self._bad(f"meta.{key}: not valid JSON") from None

    def ticks(self, every: int = 1) -> Ticks:
        rows = self._rows(
            "SELECT k, t, px, py, theta, alive, max_error_m, min_agent_gap_m, min_obstacle_gap_m, groups "
            "FROM ticks WHERE k % ? = 0 ORDER BY k", (every,))
        n = len(self.ids)
        for r in rows:  # every blob holds one value per agent; the numbers are numbers
            for col, name, size in ((2, "px", 8), (3, "py", 8), (4, "theta", 8), (5, "alive", 1)):
                if not isinstance(r[col], bytes) or len(r[col]) != n * size:
                    got = f"{len(r[col])} bytes" if isinstance(r[col], bytes) else type(r[col]).__name__
                    raise self._bad(f"ticks k={r[0]}: {name} holds {got}, expected {n * size} bytes "
                                    f"({n} agents)")
            if type(r[0]) is not int or not _number(r[1]) or not all(v is None or _number(v) for v in r[6:9]) \
                    or not (r[9] is None or type(r[9]) is int):
                raise self._bad(f"ticks k={r[0]!r}: a column of the wrong type")

        def stack(col: int, dtype: str) -> NDArray[Any]:
            if not rows:
                return np.zeros((0, n), dtype=dtype)
            return np.frombuffer(b"".join(r[col] for r in rows), dtype=dtype).reshape(len(rows), n)

        def column(col: int) -> Array:
            return np.array([np.nan if r[col] is None else r[col] for r in rows], dtype=np.float64)

        return Ticks(np.array([r[0] for r in rows], dtype=np.int64), np.array([r[1] for r in rows]),
                     stack(2, "<f8"), stack(3, "<f8"), stack(4, "<f8"), stack(5, "u1").astype(bool),
                     column(6), column(7), column(8),
                     np.array([r[9] if r[9] is not None else -1 for r in rows], dtype=np.int64))

    def events(self) -> list[dict[str, Any]]:
        out = []
        for seq, data in self._rows("SELECT seq, data FROM events ORDER BY t, seq"):
            try:
                ev = json.loads(data)
            except (TypeError, ValueError):
                raise self._bad(f"events seq={seq}: not valid JSON") from None
            if not _event_shape(ev):
                raise self._bad(f"events seq={seq}: not an event (t, kind, before, after, agent)")
            out.append(ev)
        return out

    def contacts(self) -> list[dict[str, Any]]:
        cols = ("kind", "a", "b", "t_start", "t_end", "gap_m")
        rows = self._rows(f"SELECT seq, {', '.join(cols)} FROM contacts ORDER BY t_start, seq")
        for seq, kind, a, b, t0, t1, gap in rows:
            if not (isinstance(kind, str) and isinstance(a, str) and isinstance(b, str) and _number(t0)
                    and (t1 is None or _number(t1)) and _number(gap)):
                raise self._bad(f"contacts seq={seq}: a column of the wrong type")
        return [dict(zip(cols, r[1:], strict=True)) for r in rows]

    def counters(self) -> dict[str, int]:
        rows = self._rows("SELECT process, messages_rejected FROM counters")
        if not all(isinstance(p, str) and type(n) is int for p, n in rows):
            raise self._bad("counters: a column of the wrong type")
        return dict(rows)

    def intrusions(self) -> list[dict[str, Any]]:
        """Well-formed messages refused by admission: {process, kind, source, count, first_t} rows."""
        cols = ("process", "kind", "source", "count", "first_t")
        try:
            rows = self.db.execute(f"SELECT {', '.join(cols)} FROM intrusions ORDER BY first_t, process, kind")
        except sqlite3.OperationalError:  # a record written before the table existed
            return []
        return [dict(zip(cols, r, strict=True)) for r in rows]

    def gaps(self) -> list[dict[str, Any]]:
        rows = self._rows("SELECT t_from, t_to, note FROM gaps")
        if not all(_number(a) and _number(b) and isinstance(c, str) for a, b, c in rows):
            raise self._bad("gaps: a column of the wrong type")
        return [{"t_from": a, "t_to": b, "note": c} for a, b, c in rows]


def _number(v: Any) -> bool:
    return type(v) in (int, float)


def _event_shape(ev: Any) -> bool:
    """What the readers use of an event: numeric t, text kind, groups as lists of lists of ints, agent."""
    if not isinstance(ev, dict) or not _number(ev.get("t")) or not isinstance(ev.get("kind"), str):
        return False
    for key in ("before", "after"):
        groups = ev.get(key, [])
        if not isinstance(groups, list) or not all(
                isinstance(g, list) and all(type(a) is int for a in g) for g in groups):
            return False
    return "agent" not in ev or ev["agent"] is None or type(ev["agent"]) is int
