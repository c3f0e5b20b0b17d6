"""A ROS 2 node as rmw_zenoh makes one, on an open zenoh session: what `--ros2` processes declare.

The node's liveliness token (`NN`), for each publisher a token (`MP`) and a zenoh publisher on the topic's
key whose every sample carries the 33-byte attachment (sequence number, source timestamp, gid), for each
subscription a token (`MS`) and a zenoh subscriber. Ids count from 0 within the session, nodes and their
entities alike, as rmw_zenoh counts them within a context (one zenoh session): the first node of a session is
entity 0 and its entities 1, 2, ...; a second node on the same session (an agent host's) takes the next id
and its entities the ones after. Samples reach the caller's callback with their
attachment checked: one without a valid attachment is not delivered but counted in `bad_attachments`
(read it on the caller's loop; nothing is logged or blocked inside zenoh's callback).
"""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import suppress
from typing import Any

import zenoh

from reconswarm.net import ros2
from reconswarm.net import ros2_graph as graph

QOS = graph.QoS(depth=10)  # ROS 2's default profile for topics: reliable, volatile, keep last 10
_IDS: dict[str, Iterator[int]] = {}  # session id -> its next entity id (rmw_zenoh: one counter per context)
_IDS_LOCK = threading.Lock()


def next_entity_id(session_id: str) -> int:
    """The session's next entity id (nodes and their publishers and subscriptions share one count)."""
    with _IDS_LOCK:
        return next(_IDS.setdefault(session_id, itertools.count()))


class Ros2Publisher:
    def __init__(self, session: Any, key: str) -> None:
        self.key = key
        self.publication = ros2.Publication(key)
        self.pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)

    def put(self, payload: bytes) -> None:
        self.pub.put(payload, attachment=self.publication.next_attachment(time.time_ns()))


class Ros2Node:
    """One node (`name` in namespace `/`) in ROS 2 domain `domain_id`; undeclare everything with close()."""

    def __init__(self, session: Any, domain_id: int, name: str) -> None:
        self.z, self.domain_id, self.name = session, ros2.check_domain_id(domain_id), name
        self.session_id = str(session.zid())
        self.node_id = next_entity_id(self.session_id)
        self.bad_attachments = 0
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
                ros2.unpack_attachment(None if att is None else att.to_bytes())
            except ros2.Ros2Error:
                self.bad_attachments += 1
                return
            callback(sample)

        self.entities.append(self.z.declare_subscriber(ros2.topic_key(self.domain_id, topic, type_name), on_sample))
        self._token(graph.EntityKind.SUBSCRIPTION, topic, type_name)

    def close(self) -> None:
        for x in [*self.tokens, *self.entities]:
            with suppress(Exception):
                x.undeclare()
