"""What a launch tells its user: where to connect while it runs, and the summary when it ends, however it ends.

- `--foxglove`: the live view's URL, once the monitor's server listens (it starts with the monitor, which
  on a loaded machine can take a minute); `--ros2`: the router and domain to point ROS 2 tools at;
- at the end, the summary table (or JSON) and where the record and logs are, also for a run stopped by a
  signal or by `--timeout`, whose record then says so (`end_reason` `stopped` or `timeout`, not finished).
"""

from __future__ import annotations

import json
import logging
import sys
from pathlib import Path

from rich.console import Console

from reconswarm.cli.console import mission_exit_code, unconverged_reason
from reconswarm.record.store import RunRecord, note_stop
from reconswarm.record.summary import render, summarize
from reconswarm_bringup.config import LaunchConfig
from reconswarm_bringup.network import listening

log = logging.getLogger("reconswarm.launch")
LIVE_HOST = "127.0.0.1"  # where the monitor's live view listens (monitor/live.py)


class LiveViewNotice:
    """Says the live view's URL once its server listens (polled by the launcher's loop; a bind probe, so no
    client connects to find out)."""

    def __init__(self, port: int | None) -> None:
        self.port = port
        self.said = port is None

    def poll(self) -> None:
        if not self.said and self.port is not None and listening(LIVE_HOST, self.port):
            self.said = True
            log.info("live view: ws://%s:%d (Foxglove app: Open connection > Foxglove WebSocket)", LIVE_HOST,
                     self.port)


def ros2_notice(endpoint: str, domain: int, secrets: Path | None = None) -> None:
    """Where ROS 2 tools find the run's topics (rmw_zenoh reads ZENOH_CONFIG_OVERRIDE or, for a whole
    configuration, ZENOH_SESSION_CONFIG_URI); under --secure (`secrets`: the run's credentials) a plain
    connection cannot open: a tool joins with a role's configuration."""
    log.info("ROS 2: topics /robot_<i>/odom and /robot_<i>/cmd_vel in domain %d on the Zenoh router %s", domain,
             endpoint)
    if secrets is None:
        log.info("ROS 2 tools: export RMW_IMPLEMENTATION=rmw_zenoh_cpp ROS_DOMAIN_ID=%d "
                 "ZENOH_CONFIG_OVERRIDE='connect/endpoints=[\"%s\"]'; ros2 topic list", domain, endpoint)
        return
    log.info("ROS 2 tools (--secure: TLS with a certificate, a plain connection is refused): export "
             "RMW_IMPLEMENTATION=rmw_zenoh_cpp ROS_DOMAIN_ID=%d ZENOH_SESSION_CONFIG_URI=%s; ros2 topic list "
             "(a role's rights: the observer's are the clock and events, no robot topic; docs/security.md)",
             domain, secrets / "observer.json5")


def last_line(path: Path) -> str:
    """The last line a process logged (its one-line error when it failed), without the log's time stamp."""
    try:
        lines = path.read_text(errors="replace").strip().splitlines()
    except OSError:
        return ""
    return lines[-1].split(" ", 2)[-1] if lines and lines[-1][:2].isdigit() else (lines[-1] if lines else "")


def _has_ticks(db: Path) -> bool:
    """Whether the record at db holds a tick (False: no record, or one the mission never wrote to)."""
    import sqlite3

    if not db.exists():
        return False
    try:
        con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
        try:
            return con.execute("SELECT 1 FROM ticks LIMIT 1").fetchone() is not None
        finally:
            con.close()
    except sqlite3.Error:
        return True  # a record there, unreadable: say that


def report(cfg: LaunchConfig, crashed: list[str], fatal: str | None = None, halt: str | None = None,
           warns: list[str] | None = None) -> int:
    """Print the summary and where the record is; the exit code. `halt`: the launcher ended the run early
    ("stopped" by a signal, "timeout"), which the record is made to say (the world only knows it was stopped).
    `warns`: the scenario's warnings, named as the likely reason when the run ends without converging."""
    db = cfg.out / "run.db"
    early = {"stopped": "stopped", "timeout": "timed out"}.get(halt or "", "ended")  # (before the first tick)
    try:
        if halt is not None:
            note_stop(db, halt)
        with RunRecord(db) as rec:
            summary = summarize(rec)
    except Exception as exc:  # the record itself may be what failed (disk full): say so, do not hide the cause
        if fatal is None and halt is None:
            raise
        if _has_ticks(db):
            log.error("no summary: the record cannot be read (%s)", exc)
        else:  # ended before the mission's first tick: nothing to summarize, and that is what to say
            log.error("%s during start-up: no record yet (logs: %s)", early, cfg.out / "logs")
        if fatal is not None:
            log.error("%s", fatal)
        return 3
    if cfg.as_json:
        sys.stdout.write(json.dumps(summary, indent=2) + "\n")
    else:
        Console().print(render(summary))
        print(f"record: {db}\nlogs:   {cfg.out / 'logs'}")
    sys.stdout.flush()
    if (halt is not None or fatal is not None) and not summary.get("ticks"):
        log.warning("%s during start-up: no tick recorded yet (the summary above is empty)", early)
    if halt is None and fatal is None:
        for line in unconverged_reason(summary, warns or []):
            log.warning("%s", line)
    if fatal is not None:
        log.error("%s", fatal)
        return 3
    if halt == "timeout":
        return 3
    if crashed:
        log.error("processes failed: %s", "; ".join(crashed))
        return 3
    return mission_exit_code(summary)
