"""The live view against bad clients, with real sockets on 127.0.0.1 (issue 22, case 8): clients that
subscribe and never read do not hold its close (before: the stop waited for them, over 60 s), and a client
that fails the handshake again and again does not flood the log (before: one line per connection)."""

from __future__ import annotations

import base64
import contextlib
import json
import logging
import os
import socket
import struct
import time

import numpy as np

from monitor.live import LiveView
from reconswarm.scenario.model import load
from tests.support import PAPER, wait_until

S = load(PAPER)


def _masked_text_frame(text: str) -> bytes:
    data, mask = text.encode(), os.urandom(4)
    n = len(data)
    head = bytes([0x81]) + (bytes([0x80 | n]) if n < 126 else bytes([0x80 | 126]) + struct.pack(">H", n))
    return head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(data))


def _channel_ids(view: LiveView) -> list[int]:
    """The view's channel ids (the SDK numbers channels per process: not 1..6 once other channels exist)."""
    ch = view.channels
    return [c.id() for c in (ch.world, ch.swarm, ch.events, ch.errors, ch.metrics, view.knowledge)]


def _client_that_never_reads(port: int, channels: list[int]) -> socket.socket:
    c = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    c.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    c.connect(("127.0.0.1", port))
    key = base64.b64encode(os.urandom(16)).decode()
    c.sendall((f"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
               f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
               f"Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n").encode())
    heard = bytearray()  # (the handshake's answer, then the server advertises its channels)

    def advertised() -> bool:
        with contextlib.suppress(TimeoutError):
            heard.extend(c.recv(65536))
        return b'"advertise"' in heard

    c.settimeout(0.1)
    wait_until(advertised, 10.0, "the live view's advertisement of its channels", every_s=0.0)
    c.settimeout(None)
    subs = [{"id": k, "channelId": ch} for k, ch in enumerate(channels)]
    c.sendall(_masked_text_frame(json.dumps({"op": "subscribe", "subscriptions": subs})))
    return c


def test_clients_that_never_read_do_not_hold_the_close() -> None:
    view = LiveView(S, 0, max_rate_hz=1000.0)
    clients = [_client_that_never_reads(view.port, _channel_ids(view)) for _ in range(5)]
    try:
        n = len(S.agents)
        alive, edges = np.ones(n, dtype=bool), np.zeros((0, 2), dtype=np.int64)
        sent, t0 = 0, time.monotonic()
        while time.monotonic() - t0 < 4.0:  # scenes pile up in the clients' queues and TCP windows
            sent += view.tick(time.monotonic(), sent * 0.05, S.starts, S.headings, alive, edges, 1.0, 1.0, 1.0)
            time.sleep(0.002)
        assert sent > 100 and view.listened()
        started = time.monotonic()
        view.close(timeout_s=2.0)
        assert time.monotonic() - started < 10.0  # (bounded by the timeout, not by the clients)
    finally:
        for c in clients:
            c.close()


class _Count(logging.Handler):
    def __init__(self) -> None:
        super().__init__()
        self.lines: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        if record.name.startswith("foxglove"):
            self.lines.append(record.getMessage())


def test_a_client_failing_its_handshake_again_and_again_writes_a_few_lines() -> None:
    root = logging.getLogger()
    count, level = _Count(), root.level
    root.addHandler(count)
    root.setLevel(logging.INFO)
    try:
        view = LiveView(S, 0)  # (puts the budget on the root's handlers, ours too)
        for _ in range(300):
            with socket.create_connection(("127.0.0.1", view.port)) as c:
                c.sendall(b"NOT HTTP AT ALL\r\n\r\n")
        time.sleep(1.0)
        view.close()
    finally:
        root.removeHandler(count)
        root.setLevel(level)
    failed = [line for line in count.lines if "handshake failed" in line]
    assert 1 <= len(count.lines) <= 10, len(count.lines)  # (before: 300 handshake lines and more)
    assert failed
