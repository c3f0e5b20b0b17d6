"""The zenoh session of every process: options, opening a session, serving until stopped, a liveliness member.

Every process takes the same options (`--connect EP`, `--listen EP`, `--mode peer|client|router`,
`--zenoh-config FILE.json5`); multicast scouting is off unless a config file turns it on; clients wait
for their router (and reconnect by themselves when it restarts). The inbox is reconswarm/net/runtime/inbox.py, a
process's signals and usage reconswarm/net/runtime/lifecycle.py.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from reconswarm.errors import BadInput, ProcessFailure
from reconswarm.net.runtime.lifecycle import Stopper, usage
from reconswarm.net.timing import TIMING
from reconswarm.scenario.wire_limits import MAX_PAYLOAD_BYTES

log = logging.getLogger("reconswarm")
MODES = ("peer", "client", "router")
DEFAULT_ROUTER = "tcp/127.0.0.1:7447"

# A router forwards no message with a payload over the wire's limit: every decoder refuses such a payload anyway
# (reconswarm/net/wire/wire.py), and a router that fans it out makes each receiver take it first (a flood of 1 MiB
# payloads held every agent host's loop up for seconds and ~1 GB of memory). Zenoh's own low-pass filter, on
# what the router receives; a router's own config file may set its own filter instead.
PAYLOAD_CAP = {"id": "reconswarm-payload-cap", "flows": ["ingress"], "messages": ["put", "delete", "query", "reply"],
               "key_exprs": ["**"], "size_limit": MAX_PAYLOAD_BYTES}


@dataclass(frozen=True)
class ZenohOptions:
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    mode: str = "client"
    config_file: Path | None = None

    @staticmethod
    def build(connect: list[str] | None, listen: list[str] | None, mode: str,
              config_file: Path | None) -> ZenohOptions:
        if mode not in MODES:
            raise BadInput(f"--mode: expected one of {', '.join(MODES)}, got {mode!r}")
        for ep in [*(connect or []), *(listen or [])]:
            if "/" not in ep:
                raise BadInput(f"--connect/--listen: endpoint {ep!r} is not of the form proto/address (tcp/host:port)")
        if config_file is not None and not config_file.is_file():
            raise BadInput(f"{config_file}: zenoh config file not found")
        if config_file is None and mode == "client" and not connect:
            connect = [DEFAULT_ROUTER]
        return ZenohOptions(tuple(connect or ()), tuple(listen or ()), mode, config_file)

    def config(self) -> Any:
        import zenoh

        if self.config_file is not None:
            try:
                conf = zenoh.Config.from_file(str(self.config_file))
            except Exception as exc:
                raise BadInput(f"{self.config_file}: invalid zenoh config: {exc}") from None
        else:
            conf = zenoh.Config()
            conf.insert_json5("mode", json.dumps(self.mode))
            conf.insert_json5("scouting/multicast/enabled", "false")
            conf.insert_json5("transport/link/tx/lease", str(TIMING.lease_ms))
            conf.insert_json5("connect/timeout_ms", '{"router": -1, "peer": -1, "client": 15000}')
        # Advanced publishers (late joiners' obstacle sets) need timestamps.
        conf.insert_json5("timestamping/enabled", "true")
        if self.connect:
            conf.insert_json5("connect/endpoints", json.dumps(list(self.connect)))
        if self.listen:
            conf.insert_json5("listen/endpoints", json.dumps(list(self.listen)))
        # What anyone can send to directly (a router; a peer, whose endpoint the router's gossip tells whoever asks)
        # takes no payload over the wire's limit; a client gets only what its router forwards.
        open_to_all = json.loads(conf.get_json("mode")) in ("router", "peer")
        if open_to_all and json.loads(conf.get_json("low_pass_filter")) == []:
            conf.insert_json5("low_pass_filter", json.dumps([PAYLOAD_CAP]))
        return conf


@contextmanager
def serving(opts: ZenohOptions, what: str, timeout_s: float = TIMING.session_open_timeout_s,
            zid: str | None = None) -> Iterator[tuple[Any, Stopper]]:
    """A process's session and its SIGINT/SIGTERM flag; the session is closed however the body ends. zid: the
    session's id (that of a session the process closed, which it replaces; None: a fresh one)."""
    stop = Stopper()
    session = open_session(opts, what, timeout_s, zid)
    try:
        yield session, stop
    finally:
        session.close()
        log.info("usage: %s", usage())


class Member:
    """A process that announces itself with a liveliness token (closing withdraws it)."""

    token: Any

    def close(self) -> None:
        with suppress(Exception):
            self.token.undeclare()


def open_session(opts: ZenohOptions, what: str, timeout_s: float = TIMING.session_open_timeout_s,
                 zid: str | None = None) -> Any:
    """Open a session, retrying until the router answers or the timeout passes (then ProcessFailure). zid: its id
    (a router refuses it while it still holds a session of that id: until that one's close or lease is through)."""
    import zenoh

    deadline = time.monotonic() + timeout_s
    last: Exception | None = None
    while time.monotonic() < deadline:
        try:
            conf = opts.config()
            if zid is not None:
                conf.insert_json5("id", json.dumps(zid))
            return zenoh.open(conf)
        except BadInput:
            raise
        except Exception as exc:  # zenoh.ZError: router not up yet, port in use, ...
            last = exc
            time.sleep(0.2)
    raise ProcessFailure(f"{what}: cannot open a zenoh session ({', '.join(opts.connect or opts.listen)}): {last}")
