"""The ROS 2 face (reconswarm.net.ros2.ros2): bytes checked by rosbags' own CDR decoder and by the CDR layout,
keys, attachment and liveliness tokens checked against the example lines of rmw_zenoh's docs/design.md
(github.com/ros2/rmw_zenoh, docs/design.md, sections "Topic and Service name mapping to Zenoh key
expressions", "Graph Cache" and "Publishers"), quoted verbatim below, not against our own output."""

from __future__ import annotations

import math
import struct
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rosbags.typesys import Stores, get_typestore

from reconswarm.errors import BadInput
from reconswarm.net.ros2 import ros2
from reconswarm.net.ros2 import ros2_graph as graph

STORE = get_typestore(Stores.ROS2_JAZZY)
T: Any = STORE.types

# --- rmw_zenoh docs/design.md, "Topic and Service name mapping to Zenoh key expressions", examples:
DOC_CHATTER_KEY = (
    "0/chatter/std_msgs::msg::dds_::String_/RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
)
DOC_NS_CHATTER_KEY = (
    "0/robot1/chatter/std_msgs::msg::dds_::String_/RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
)
DOC_SERVICE_KEY = (
    "2/add_two_ints/example_interfaces::srv::dds_::AddTwoInts_/"
    "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"
)
# --- rmw_zenoh docs/design.md, "Graph Cache", examples using the demo_nodes_cpp package:
DOC_LISTENER_NODE = "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
DOC_LISTENER_SUB = (
    "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/std_msgs::msg::dds_::String_/"
    "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,10:,:,:,,"
)
DOC_TALKER_PUB = (
    "@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/"
    "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,7:,:,:,,"
)
DOC_SERVICE_SERVER = (
    "@ros2_lv/2/f9980ee0495eaafb3e38f0d19e2eae12/0/10/SS/%/%/add_two_ints_server/%add_two_ints/"
    "example_interfaces::srv::dds_::AddTwoInts_/RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a/"
    "::,10:,:,:,,"
)
DOC_SERVICE_CLIENT = (
    "@ros2_lv/2/e1dc8d1b45ae8717fce78689cc655685/0/10/SC/%/%/add_two_ints_client/%add_two_ints/"
    "example_interfaces::srv::dds_::AddTwoInts_/RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a/"
    "::,10:,:,:,,"
)
# Published type hashes of ROS 2 Jazzy's types, as `ros2 topic info --verbose` prints them ("Topic type hash:")
# and as independent public ROS 2 client libraries pin them in their golden-hash tests.
PUBLISHED_TWIST_HASH = "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
PUBLISHED_ODOMETRY_HASH = "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"

SESSION = "aac3178e146ba6f1fc6e6a4085e77f21"


# ------------------------------------------------------------------------------------------------ keys


def test_rosbags_hash_matches_the_design_document_and_published_hashes():
    # the String hash in the design document's key is what rosidl computed: same algorithm as rosbags'
    assert ros2.type_hash("std_msgs/msg/String") == DOC_CHATTER_KEY.rsplit("/", 1)[1]
    assert ros2.type_hash(ros2.TWIST) == PUBLISHED_TWIST_HASH
    assert ros2.type_hash(ros2.ODOMETRY) == PUBLISHED_ODOMETRY_HASH


def test_topic_keys_match_the_design_document():
    assert ros2.topic_key(0, "/chatter", "std_msgs/msg/String") == DOC_CHATTER_KEY
    assert ros2.topic_key(0, "/robot1/chatter", "std_msgs/msg/String") == DOC_NS_CHATTER_KEY
    assert ros2.dds_type_name("example_interfaces/srv/AddTwoInts") == DOC_SERVICE_KEY.split("/")[2]
    parsed = ros2.parse_topic_key(DOC_NS_CHATTER_KEY)
    assert (parsed.domain_id, parsed.topic, parsed.dds_type) == (0, "/robot1/chatter", "std_msgs::msg::dds_::String_")
    assert ros2.parse_topic_key(DOC_SERVICE_KEY).domain_id == 2


def test_robot_keys_follow_the_same_layout():
    assert ros2.odom_key(3, 12) == f"3/robot_12/odom/nav_msgs::msg::dds_::Odometry_/{PUBLISHED_ODOMETRY_HASH}"
    assert ros2.cmd_vel_key(0, 0) == f"0/robot_0/cmd_vel/geometry_msgs::msg::dds_::Twist_/{PUBLISHED_TWIST_HASH}"
    assert ros2.agent_of_topic(ros2.parse_topic_key(ros2.odom_key(0, 7)).topic) == 7
    for bad in ("/robot_01/odom", "/robot_x/odom", "/robot_1/scan", "robot_1/odom"):
        with pytest.raises(ros2.Ros2Error):
            ros2.agent_of_topic(bad)
    for bad in ("0/chatter", "x/chatter/std_msgs::msg::dds_::String_/RIHS01_0", "0//a/b::dds_::c/RIHS01_0"):
        with pytest.raises(ros2.Ros2Error):
            ros2.parse_topic_key(bad)
    with pytest.raises(ValueError):
        ros2.odom_key(233, 0)


def test_domain_id_from_option_then_environment_then_zero():
    assert ros2.resolve_domain_id(5, {"ROS_DOMAIN_ID": "7"}) == 5
    assert ros2.resolve_domain_id(None, {"ROS_DOMAIN_ID": "7"}) == 7
    assert ros2.resolve_domain_id(None, {}) == 0
    assert ros2.resolve_domain_id(None, {"ROS_DOMAIN_ID": " "}) == 0
    for option, env in ((None, {"ROS_DOMAIN_ID": "seven"}), (None, {"ROS_DOMAIN_ID": "233"}), (-1, {})):
        with pytest.raises(BadInput, match=r"ROS_DOMAIN_ID|--ros-domain-id"):
            ros2.resolve_domain_id(option, env)


# ------------------------------------------------------------------------------------ liveliness tokens


def test_tokens_built_as_in_the_design_document():
    assert graph.node_token(2, SESSION, 0, "listener") == DOC_LISTENER_NODE
    sub = graph.endpoint_token(graph.EntityKind.SUBSCRIPTION, 2, SESSION, 0, 10, "listener", "/chatter",
                           "std_msgs/msg/String", graph.QoS(depth=10))
    assert sub == DOC_LISTENER_SUB
    pub = graph.endpoint_token(graph.EntityKind.PUBLISHER, 2, "8b20917502ee955ac4476e0266340d5c", 0, 10, "talker",
                           "/chatter", "std_msgs/msg/String", graph.QoS(depth=7))
    assert pub == DOC_TALKER_PUB


@pytest.mark.parametrize("line", [DOC_LISTENER_NODE, DOC_LISTENER_SUB, DOC_TALKER_PUB, DOC_SERVICE_SERVER,
                                  DOC_SERVICE_CLIENT])
def test_tokens_of_the_design_document_parse_and_rebuild(line):
    entity = graph.parse_token(line)
    assert entity.keyexpr() == line
    parts = line.split("/")
    assert (entity.domain_id, entity.session_id, entity.node_id, entity.entity_id) == (
        int(parts[1]), parts[2], int(parts[3]), int(parts[4]))
    assert (entity.kind.value, entity.enclave, entity.namespace, entity.node_name) == (parts[5], "/", "/", parts[8])
    if entity.topic is not None:
        assert entity.topic.name == "/" + parts[9][1:].replace("%", "/")
        assert (entity.topic.dds_type, entity.topic.type_hash) == (parts[10], parts[11])


def test_token_of_a_namespaced_robot_topic():
    key = graph.endpoint_token(graph.EntityKind.PUBLISHER, 0, "1f", 3, 4, "simworld", "/robot_2/odom", ros2.ODOMETRY,
                           graph.QoS(depth=10), namespace="/swarm")
    assert key == (f"@ros2_lv/0/1f/3/4/MP/%/%swarm/simworld/%robot_2%odom/nav_msgs::msg::dds_::Odometry_/"
                   f"{PUBLISHED_ODOMETRY_HASH}/::,10:,:,:,,")
    e = graph.parse_token(key)
    assert e.namespace == "/swarm" and e.topic is not None and e.topic.name == "/robot_2/odom"


def test_qos_compact_form():
    # rmw_zenoh's qos_to_keyexpr: defaults (reliable, volatile, keep_last, depth 42) are left empty
    assert graph.QoS().to_keyexpr() == "::,:,:,:,,"
    q = graph.QoS(graph.Reliability.BEST_EFFORT, graph.Durability.TRANSIENT_LOCAL, graph.History.KEEP_ALL, 5)
    assert q.to_keyexpr() == "2:1:2,5:,:,:,,"
    assert graph.QoS.from_keyexpr("2:1:2,5:,:,:,,") == q
    assert graph.QoS.from_keyexpr("::,10:,:,:,,") == graph.QoS(depth=10)
    for bad in ("::,10", "9::,:,:,:,,", "::,x:,:,:,,", "::,:,:,:,", "a:b:c:d:e:f"):
        with pytest.raises(ros2.Ros2Error):
            graph.QoS.from_keyexpr(bad)


@pytest.mark.parametrize("bad", [
    "@ros2_lv/2/aac3/0/0/NN/%/%",  # too short
    "@other/2/aac3/0/0/NN/%/%/listener",
    "@ros2_lv/2/aac3/0/0/XX/%/%/listener",
    "@ros2_lv/2/AAC3/0/0/NN/%/%/listener",  # session ids are lowercase hex
    "@ros2_lv/x/aac3/0/0/NN/%/%/listener",
    "@ros2_lv/2/aac3/0/0/NN/%/%/listener/%chatter",  # a node token has no topic
    DOC_TALKER_PUB.rsplit("/", 1)[0],  # a publisher token needs its QoS
    DOC_TALKER_PUB.replace("/talker/", "//"),
])
def test_malformed_tokens_are_rejected(bad):
    with pytest.raises(ros2.Ros2Error):
        graph.parse_token(bad)


# ------------------------------------------------------------------------------------------ attachment


def test_attachment_layout_of_the_design_document():
    # design.md, "Publishers": 8 bytes sequence number (int64 LE), 8 bytes timestamp (ns since the UNIX epoch,
    # int64 LE), 1 byte gid length (always 16), 16 bytes gid.
    gid = bytes(range(100, 116))
    raw = ros2.pack_attachment(ros2.Attachment(-2, 1_764_000_000_123_456_789, gid))
    seq_le = (-2).to_bytes(8, "little", signed=True)
    expected = seq_le + (1_764_000_000_123_456_789).to_bytes(8, "little") + b"\x10" + gid
    assert raw == expected and len(raw) == 33
    assert ros2.unpack_attachment(raw) == ros2.Attachment(-2, 1_764_000_000_123_456_789, gid)


@pytest.mark.parametrize("raw", [None, b"", bytes(32), bytes(34), bytes(16) + b"\x0f" + bytes(16)])
def test_bad_attachments_are_rejected(raw):
    with pytest.raises(ros2.Ros2Error):
        ros2.unpack_attachment(raw)


def test_publication_numbers_its_samples_with_one_random_gid():
    a, b = ros2.Publication("k"), ros2.Publication("k")
    assert a.gid != b.gid and len(a.gid) == 16
    atts = [ros2.unpack_attachment(a.next_attachment(1000 + i)) for i in range(3)]
    assert [x.sequence_number for x in atts] == [1, 2, 3]
    assert [x.source_timestamp_ns for x in atts] == [1000, 1001, 1002]
    assert {x.gid for x in atts} == {a.gid}
    for bad in (ros2.Attachment(1, 1, bytes(15)), ros2.Attachment(2**63, 1, bytes(16))):
        with pytest.raises(ValueError):
            ros2.pack_attachment(bad)


# ------------------------------------------------------------------------------------------ CDR payloads


def test_odometry_bytes_as_rosbags_decodes_them():
    raw = ros2.odom_to_ros(ros2.Odom(4, 222.25, 3.5, -1.25, math.pi / 3, 0.4, -0.2))
    assert raw[:4] == b"\x00\x01\x00\x00"  # CDR_LE encapsulation
    msg: Any = STORE.deserialize_cdr(raw, "nav_msgs/msg/Odometry")
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (222, 250_000_000)
    assert (msg.header.frame_id, msg.child_frame_id) == ("odom", "robot_4/base_link")
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    assert (p.x, p.y, p.z) == (3.5, -1.25, 0.0)
    assert (q.x, q.y) == (0.0, 0.0)
    assert q.z == pytest.approx(0.5) and q.w == pytest.approx(math.sqrt(3) / 2)  # yaw pi/3 about z
    assert (msg.twist.twist.linear.x, msg.twist.twist.angular.z) == (0.4, -0.2)


def test_twist_bytes_follow_the_cdr_layout():
    # CDR: 4-byte encapsulation header (0x0001 = little-endian), then linear and angular as six float64
    raw = ros2.twist_to_ros(0.75, -0.5)
    assert raw == b"\x00\x01\x00\x00" + struct.pack("<6d", 0.75, 0, 0, 0, 0, -0.5)
    msg: Any = STORE.deserialize_cdr(raw, "geometry_msgs/msg/Twist")
    assert (msg.linear.x, msg.angular.z) == (0.75, -0.5)


def _rosbags_odometry(child: str = "robot_2/base_link", frame: str = "odom", q=(0.0, 0.0, 0.0, 1.0), x=1.0):
    v3 = T["geometry_msgs/msg/Vector3"]
    return T["nav_msgs/msg/Odometry"](
        header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=7, nanosec=5), frame_id=frame),
        child_frame_id=child,
        pose=T["geometry_msgs/msg/PoseWithCovariance"](
            pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=x, y=2.0, z=0.0),
                                             orientation=T["geometry_msgs/msg/Quaternion"](*q)),
            covariance=np.zeros(36)),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](linear=v3(0.1, 0.0, 0.0), angular=v3(0.0, 0.0, 0.2)),
            covariance=np.zeros(36)))


def test_messages_made_by_rosbags_decode():
    for little_endian in (True, False):
        raw = bytes(STORE.serialize_cdr(_rosbags_odometry(q=(0.0, 0.0, 1.0, 0.0)), ros2.ODOMETRY,
                                        little_endian=little_endian))
        assert ros2.odom_from_ros(raw, 2) == ros2.Odom(2, 7.000000005, 1.0, 2.0, math.pi, 0.1, 0.2)
    v3 = T["geometry_msgs/msg/Vector3"]
    twist = T["geometry_msgs/msg/Twist"](linear=v3(0.3, 9.0, 9.0), angular=v3(9.0, 9.0, -0.7))
    assert ros2.twist_from_ros(bytes(STORE.serialize_cdr(twist, ros2.TWIST, little_endian=True))) == (0.3, -0.7)


@pytest.mark.parametrize("msg, agent", [
    (_rosbags_odometry(frame="map"), 2),
    (_rosbags_odometry(child="base_link"), 2),
    (_rosbags_odometry(), 3),  # robot_2's frame on robot_3's topic
    (_rosbags_odometry(child="robot_02/base_link"), 2),  # (agent ids are read in their canonical form alone)
    (_rosbags_odometry(child="robot_٢/base_link"), 2),
    (_rosbags_odometry(child="robot_²/base_link"), 2),
    (_rosbags_odometry(q=(0.1, 0.0, 0.0, 0.995)), 2),  # rolled: not a planar pose
    (_rosbags_odometry(q=(0.0, 0.0, 0.0, 2.0)), 2),  # not a unit quaternion
    (_rosbags_odometry(x=math.nan), 2),
])
def test_odometry_that_does_not_fit_is_rejected(msg, agent):
    with pytest.raises(ros2.Ros2Error):
        ros2.odom_from_ros(bytes(STORE.serialize_cdr(msg, ros2.ODOMETRY, little_endian=True)), agent)


def test_truncated_oversized_and_foreign_payloads_are_rejected():
    good = ros2.odom_to_ros(ros2.Odom(1, 1.0, 0.0, 0.0, 0.0))
    for raw in (good[:-9], b"", good[:3], b"\x00\x07" + good[2:], good + bytes(ros2.MAX_PAYLOAD_BYTES)):
        with pytest.raises(ros2.Ros2Error):
            ros2.odom_from_ros(raw)
    with pytest.raises(ros2.Ros2Error):
        ros2.twist_from_ros(b"\x00\x01\x00\x00" + struct.pack("<6d", math.inf, 0, 0, 0, 0, 0))
    with pytest.raises(ros2.Ros2Error):
        ros2.twist_from_ros(good)  # an Odometry is not a Twist
    with pytest.raises(ValueError):
        ros2.twist_to_ros(math.nan, 0.0)
    with pytest.raises(ValueError):
        ros2.odom_to_ros(ros2.Odom(1, -1.0, 0.0, 0.0, 0.0))


finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 10_000), st.floats(0, 1e6), finite, finite, st.floats(-10.0, 10.0), finite, finite)
def test_odometry_round_trip(aid, t, x, y, theta, v, omega):
    back = ros2.odom_from_ros(ros2.odom_to_ros(ros2.Odom(aid, t, x, y, theta, v, omega)), aid)
    assert (back.agent_id, back.x_m, back.y_m, back.v_mps, back.omega_radps) == (aid, x, y, v, omega)
    assert abs(back.t_s - t) <= 1e-9 + 1e-15 * t  # nanosecond stamp
    d = math.remainder(back.theta_rad - theta, 2 * math.pi)  # same heading, angle wrapped
    assert abs(d) < 1e-9 and -math.pi <= back.theta_rad <= math.pi


@settings(max_examples=200, deadline=None)
@given(st.floats(-ros2.MAX_MAGNITUDE, ros2.MAX_MAGNITUDE), st.floats(-ros2.MAX_MAGNITUDE, ros2.MAX_MAGNITUDE))
def test_twist_round_trip(v, omega):
    assert ros2.twist_from_ros(ros2.twist_to_ros(v, omega)) == (v, omega)


@settings(max_examples=100, deadline=None)
@given(st.floats(allow_nan=False, allow_infinity=False).filter(lambda x: abs(x) > ros2.MAX_MAGNITUDE), st.booleans())
def test_twists_beyond_any_robot_are_refused(big, turn):
    with pytest.raises(ros2.Ros2Error, match="beyond"):
        ros2.twist_from_ros(ros2.twist_to_ros(0.0, big) if turn else ros2.twist_to_ros(big, 0.0))


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=800))
def test_garbage_only_ever_raises_ros2error(raw):
    for decode in (ros2.odom_from_ros, ros2.twist_from_ros):
        try:
            out = decode(b"\x00\x01\x00\x00" + raw)
        except ros2.Ros2Error:
            continue
        values = (out.x_m, out.y_m, out.theta_rad, out.t_s) if isinstance(out, ros2.Odom) else out
        assert all(math.isfinite(v) for v in values)  # whatever decodes is usable
