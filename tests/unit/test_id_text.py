"""An agent id written as text (a key, a topic, an option) is read in one place and only in its canonical form
(issue 51): ASCII digits, no leading zero, in 0..MAX_AGENT_ID. `²` (isdigit, but int() raises), `٣` (int() reads
3) and `03` (another zenoh key than agent 3's) are no ids, wherever they come from."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from reconswarm.errors import BadInput
from reconswarm.net.ros2 import ros2
from reconswarm.net.wire.keys import Keys, WireError
from reconswarm.net.wire.report import Report
from reconswarm.scenario.wire_limits import MAX_AGENT_ID, agent_id_from_text, int_from_text
from reconswarm_bringup import faults

NOT_IDS = ["", "²", "٣", "١٢", "０", "03", "00", "+3", "-0", "-1", " 3", "3 ", "3\n", "1_000", "3.0", "0x3", "٣3",
           str(MAX_AGENT_ID + 1), "9" * 11, "1" * 5000]


@pytest.mark.parametrize("text", NOT_IDS)
def test_what_is_no_agent_id(text: str) -> None:
    assert agent_id_from_text(text) is None


@settings(max_examples=300, deadline=None)
@given(st.integers(min_value=0, max_value=MAX_AGENT_ID))
def test_an_id_is_read_from_its_canonical_decimal_alone(aid: int) -> None:
    assert agent_id_from_text(str(aid)) == aid
    assert agent_id_from_text("0" + str(aid)) is None


@settings(max_examples=500, deadline=None)
@given(st.text(max_size=14))
def test_any_text_reads_as_the_id_it_writes_or_none(text: str) -> None:
    aid = agent_id_from_text(text)
    assert aid is None or str(aid) == text


def test_signed_range() -> None:
    assert int_from_text("-7", -9, 9) == -7 and int_from_text("0", -9, 9) == 0
    assert int_from_text("-0", -9, 9) is None and int_from_text("-10", -9, 9) is None
    assert int_from_text("10", -9, 9) is None


@pytest.mark.parametrize("bad", [f"agent/{t}/state" for t in ("²", "٣", "03", "+3", "")]
                         + [f"alive/agent/{t}" for t in ("²", "٣", "03", "00", str(MAX_AGENT_ID + 1))]
                         + [f"report/agent-{t}" for t in ("²", "٣", "03", "")]
                         + [f"cell/0_0/agent/{t}/obstacles" for t in ("²", "٣", "03")]
                         + ["cell/00_0/agent/3/obstacles", "cell/-0_0/agent/3/obstacles", "cell/²_0/host/3/beacons"])
def test_keys_with_a_non_canonical_id_are_wire_errors(bad: str) -> None:
    with pytest.raises(WireError, match=r"^bad "):
        Keys("paper").parse(f"swarm/paper/{bad}")


def test_keys_read_the_largest_id() -> None:
    k = Keys("paper")
    assert k.parse(k.alive_agent(MAX_AGENT_ID)) == ("alive", MAX_AGENT_ID, "agent")
    assert k.parse(k.report(f"agent-{MAX_AGENT_ID}")) == ("report", MAX_AGENT_ID, f"agent-{MAX_AGENT_ID}")
    assert k.parse(k.host_beacons((-1, 0), 0)) == ("host", 0, "beacons")


@pytest.mark.parametrize("process", ["agent-²", "agent-03", "agent-", "world"])
def test_a_report_in_no_process_s_name_is_a_wire_error(process: str) -> None:
    with pytest.raises(WireError, match="field 'process'"):
        _ = Report(process, None).agent_id


def test_robot_topics_read_ids_canonically() -> None:
    assert ros2.agent_of_topic(f"/robot_{MAX_AGENT_ID}/odom") == MAX_AGENT_ID
    for bad in ("/robot_03/odom", "/robot_²/odom", "/robot_٣/cmd_vel", f"/robot_{MAX_AGENT_ID + 1}/odom"):
        with pytest.raises(ros2.Ros2Error):
            ros2.agent_of_topic(bad)
    top = ros2.Odom(MAX_AGENT_ID, 1.0, 0.0, 0.0, 0.0)
    assert ros2.odom_from_ros(ros2.odom_to_ros(top), MAX_AGENT_ID) == top  # (its frame robot_2147483647/base_link)
    with pytest.raises(ros2.Ros2Error):
        ros2.parse_topic_key("²/robot_1/odom/nav_msgs::msg::dds_::Odometry_/RIHS01_00")


@pytest.mark.parametrize("spec", ["kill:agent:٣@60", "kill:agent:03@60", "kill:agent:²@60", "kill:agent:3@٦0",
                                  f"kill:agent:{MAX_AGENT_ID + 1}@60"])
def test_fault_agent_ids_are_canonical(spec: str) -> None:
    with pytest.raises(BadInput, match=r"^--fault "):
        faults.parse(spec)
    assert faults.parse("kill:agent:3@60").agent_id == 3


@pytest.mark.parametrize("address", ["tcp://127.0.0.1:²", "127.0.0.1:٨٧٨٦"])
def test_a_scheduler_port_in_other_digits_is_one_line(address: str) -> None:
    from reconswarm_bringup.sweep_exec import _scheduler

    with pytest.raises(BadInput, match=r"^--dask: "):
        _scheduler(address)
