"""rmw_zenoh's liveliness tokens: how ROS 2 tools (`ros2 node list`, `ros2 topic list`) see our entities.

Layout (rmw_zenoh `docs/design.md`, "Graph Cache"):
`@ros2_lv/<domain>/<session id>/<node id>/<entity id>/<kind>/<enclave>/<namespace>/<node name>` for a node
(`NN`, entity id = node id), followed by `/<topic>/<dds type>/<type hash>/<qos>` for a publisher (`MP`) or a
subscription (`MS`); every name has its '/' mangled to '%'. Pure: the caller declares the tokens.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import Enum, IntEnum

from reconswarm.net.ros2.ros2 import Ros2Error, check_domain_id, dds_type_name, type_hash

ADMIN_SPACE = "@ros2_lv"


class EntityKind(Enum):
    NODE = "NN"
    PUBLISHER = "MP"
    SUBSCRIPTION = "MS"
    SERVICE = "SS"
    CLIENT = "SC"


class Reliability(IntEnum):  # rmw/types.h values
    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2


class Durability(IntEnum):
    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2


class History(IntEnum):
    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2


@dataclass(frozen=True)
class QoS:
    """The QoS a token advertises. Defaults are rmw_zenoh's, which the compact form leaves out;
    deadline, lifespan and liveliness are always rmw_zenoh's defaults (infinite, automatic)."""

    reliability: Reliability = Reliability.RELIABLE
    durability: Durability = Durability.VOLATILE
    history: History = History.KEEP_LAST
    depth: int = 42

    def to_keyexpr(self) -> str:
        d = QoS()

        def part(value: int, default: int) -> str:
            return "" if value == default else str(int(value))

        rel, dur = part(self.reliability, d.reliability), part(self.durability, d.durability)
        hist, depth = part(self.history, d.history), part(self.depth, d.depth)
        return f"{rel}:{dur}:{hist},{depth}:,:,:,,"

    @classmethod
    def from_keyexpr(cls, text: str) -> QoS:
        parts = text.split(":")
        subs = [p.split(",") for p in parts]
        if len(parts) != 6 or [len(s) for s in subs[2:]] != [2, 2, 2, 3]:
            raise Ros2Error(f"QoS {text!r} is not <rel>:<dur>:<hist>,<depth>:<dl>:<ls>:<lv>")
        if not all(x == "" or (x.isascii() and x.isdigit()) for s in subs for x in s):
            raise Ros2Error(f"QoS {text!r} has a non-numeric component")
        d = cls()
        try:
            return cls(
                reliability=Reliability(int(parts[0])) if parts[0] else d.reliability,
                durability=Durability(int(parts[1])) if parts[1] else d.durability,
                history=History(int(subs[2][0])) if subs[2][0] else d.history,
                depth=int(subs[2][1]) if subs[2][1] else d.depth,
            )
        except ValueError as exc:
            raise Ros2Error(f"QoS {text!r}: {exc}") from exc


def mangle(name: str) -> str:
    return name.replace("/", "%")


def demangle(name: str) -> str:
    return name.replace("%", "/")


@dataclass(frozen=True)
class Topic:
    """The topic part of a publisher's or subscription's token."""

    name: str  # fully qualified, e.g. /robot_0/odom
    dds_type: str
    type_hash: str
    qos: QoS


@dataclass(frozen=True)
class Entity:
    """One liveliness token: a node (topic None) or a publisher/subscription of a node."""

    domain_id: int
    session_id: str  # the Zenoh session id as Zenoh prints it (lowercase hex)
    node_id: int
    entity_id: int
    kind: EntityKind
    enclave: str
    namespace: str
    node_name: str
    topic: Topic | None = None

    def keyexpr(self) -> str:
        head = [ADMIN_SPACE, str(check_domain_id(self.domain_id)), self.session_id, str(self.node_id),
                str(self.entity_id), self.kind.value, mangle(self.enclave), mangle(self.namespace),
                mangle(self.node_name)]
        if (self.topic is None) != (self.kind is EntityKind.NODE):
            raise ValueError(f"a {self.kind.name} token {'needs' if self.topic is None else 'has no'} topic")
        if self.topic is not None:
            t = self.topic
            head += [mangle(t.name), mangle(t.dds_type), mangle(t.type_hash), t.qos.to_keyexpr()]
        if not all(head) or not _HEX.fullmatch(self.session_id):
            raise ValueError(f"token parts must be non-empty and the session id hex: {head!r}")
        return "/".join(head)


_HEX = re.compile(r"[0-9a-f]{1,32}")


def node_token(domain_id: int, session_id: str, node_id: int, node_name: str, namespace: str = "/",
               enclave: str = "/") -> str:
    """`NN` token of a node (its entity id is its node id, as rmw_zenoh does)."""
    return Entity(domain_id, session_id, node_id, node_id, EntityKind.NODE, enclave, namespace, node_name).keyexpr()


def endpoint_token(kind: EntityKind, domain_id: int, session_id: str, node_id: int, entity_id: int,
                   node_name: str, topic: str, type_name: str, qos: QoS | None = None, namespace: str = "/",
                   enclave: str = "/") -> str:
    """`MP` (publisher) or `MS` (subscription) token of `node_name` on `topic` of ROS type `type_name`."""
    if kind not in (EntityKind.PUBLISHER, EntityKind.SUBSCRIPTION):
        raise ValueError(f"endpoint_token is for publishers and subscriptions, not {kind.name}")
    t = Topic(topic, dds_type_name(type_name), type_hash(type_name), QoS() if qos is None else qos)
    return Entity(domain_id, session_id, node_id, entity_id, kind, enclave, namespace, node_name, t).keyexpr()


def parse_token(key: str) -> Entity:
    """Parse any `@ros2_lv/...` token (what an outside tool watching the graph needs)."""
    parts = key.split("/")
    if len(parts) < 9 or parts[0] != ADMIN_SPACE or not all(parts):
        raise Ros2Error(f"not an rmw_zenoh liveliness token: {key!r}")
    try:
        kind = EntityKind(parts[5])
    except ValueError as exc:
        raise Ros2Error(f"token {key!r}: unknown entity kind {parts[5]!r}") from exc
    if not all(p.isascii() and p.isdigit() for p in (parts[1], parts[3], parts[4])) or not _HEX.fullmatch(parts[2]):
        raise Ros2Error(f"token {key!r}: domain, node and entity ids must be numbers, the session id hex")
    want = 9 if kind is EntityKind.NODE else 13
    if len(parts) != want:
        raise Ros2Error(f"token {key!r}: {len(parts)} parts, a {kind.name} token has {want}")
    topic = None
    if kind is not EntityKind.NODE:
        topic = Topic(demangle(parts[9]), demangle(parts[10]), demangle(parts[11]), QoS.from_keyexpr(parts[12]))
    return Entity(int(parts[1]), parts[2], int(parts[3]), int(parts[4]), kind, demangle(parts[6]),
                  demangle(parts[7]), demangle(parts[8]), topic)
