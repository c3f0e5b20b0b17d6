"""A ROS 2 node as rmw_zenoh makes one, on an open zenoh session: what `--ros2` processes declare.

The node's liveliness token (`NN`), for each publisher a token (`MP`) and a zenoh publisher on the topic's
key whose every sample carries the 33-byte attachment (sequence number, source timestamp, gid), for each
subscription a token (`MS`) and a zenoh subscriber. Ids count from 0 within the session, nodes and their
entities alike, as rmw_zenoh counts them within a context (one zenoh session): the first node of a session is
entity 0 and its entities 1, 2, ...; a second node on the same session (an agent host's) takes the next id
and its entities the ones after. Samples reach the caller's callback with their
attachment checked: one without a valid attachment is not delivered but counted in `bad_attachments`
(read it on the caller's loop; nothing is logged or blocked inside zenoh's callback); the attachment's source
timestamp of each delivered sample waits in `sent` for the caller's decoder (the inbox keeps a sample's key
and bytes, not its attachment).
"""

from __future__ import annotations

import itertools
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import suppress
from typing import Any

import zenoh

from reconswarm.net.ros2 import ros2
from reconswarm.net.ros2 import ros2_graph as graph

QOS = graph.QoS(depth=10)  # ROS 2's default profile for topics: reliable, volatile, keep last 10
_IDS: dict[str, Iterator[int]] = {}  # session id -> its next entity id (rmw_zenoh: one counter per context)
_IDS_LOCK = threading.Lock()


def next_entity_id(session_id: str) -> int:
    """The session's next entity id (nodes and their publishers and subscriptions share one count)."""
    with _IDS_LOCK:
        return next(_IDS.setdefault(session_id, itertools.count()))


class SentTimes:
    """When each delivered sample was published (its attachment's source timestamp, ns since the epoch on the
    publisher's clock), by its bytes, until the caller's decoder takes it: samples with equal bytes are taken
    in the order they came. Bounded: past `LIMIT` distinct payloads nobody took, it starts afresh."""

    LIMIT = 4096

    def __init__(self) -> None:
        self._lock = threading.Lock()  # (noted in zenoh's thread, taken on the process's loop)
        self._by_payload: dict[bytes, deque[int]] = {}

    def note(self, payload: bytes, sent_ns: int) -> None:
        with self._lock:
            if len(self._by_payload) >= self.LIMIT:
                self._by_payload.clear()
            self._by_payload.setdefault(payload, deque()).append(sent_ns)

    def take(self, payload: bytes) -> int | None:
        """When the oldest sample with these bytes not taken yet was published (None: none noted)."""
        with self._lock:
            got = self._by_payload.get(payload)
            if not got:
                return None
            sent_ns = got.popleft()
            if not got:
                del self._by_payload[payload]
            return sent_ns


class Ros2Publisher:
    def __init__(self, session: Any, key: str) -> None:
        self.key = key
        self.publication = ros2.Publication(key)
        self.pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)

    def put(self, payload: bytes, now_ns: int | None = None) -> None:
        """Publish with the attachment's source timestamp `now_ns` (ns since the epoch; None: now)."""
        self.pub.put(payload, attachment=self.publication.next_attachment(time.time_ns() if now_ns is None else now_ns))


class Ros2Node:
    """One node (`name` in namespace `/`) in ROS 2 domain `domain_id`; undeclare everything with close()."""

    def __init__(self, session: Any, domain_id: int, name: str) -> None:
        self.z, self.domain_id, self.name = session, ros2.check_domain_id(domain_id), name
        self.session_id = str(session.zid())
        self.node_id = next_entity_id(self.session_id)
        self.bad_attachments = 0
        self.sent = SentTimes()  # when each sample the subscriptions delivered was published
        self.tokens = [session.liveliness().declare_token(
            graph.node_token(domain_id, self.session_id, self.node_id, name))]
        self.entities: list[Any] = []

    def _token(self, kind: graph.EntityKind, topic: str, type_name: str) -> str:
        key = graph.endpoint_token(kind, self.domain_id, self.session_id, self.node_id,
                                   next_entity_id(self.session_id), self.name, topic, type_name, QOS)
        self.tokens.append(self.z.liveliness().declare_token(key))
        return key

    def publisher(self, topic: str, type_name: str) -> Ros2Publisher:
        pub = Ros2Publisher(self.z, ros2.topic_key(self.domain_id, topic, type_name))
        self._token(graph.EntityKind.PUBLISHER, topic, type_name)
        self.entities.append(pub.pub)
        return pub

    def subscription(self, topic: str, type_name: str, callback: Callable[[Any], None]) -> None:
        """callback(sample) for each sample whose attachment is valid (called in zenoh's thread: hand over)."""

        def on_sample(sample: Any) -> None:
            att = sample.attachment
            try:
                got = ros2.unpack_attachment(None if att is None else att.to_bytes())
            except ros2.Ros2Error:
                self.bad_attachments += 1
                return
            self.sent.note(sample.payload.to_bytes(), got.source_timestamp_ns)
            callback(sample)

        self.entities.append(self.z.declare_subscriber(ros2.topic_key(self.domain_id, topic, type_name), on_sample))
        self._token(graph.EntityKind.SUBSCRIPTION, topic, type_name)

    def close(self) -> None:
        for x in [*self.tokens, *self.entities]:
            with suppress(Exception):
                x.undeclare()
