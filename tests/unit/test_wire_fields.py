"""Decoder rules that mutmut found no test for (bench/mutation.py on reconswarm/net/wire/wire.py): a command
claiming another agent's id on an agent's key, a beacon's optional revision and its range, the truth's and an
event's agent ids at their bounds, and malformed event groups; each refused with a WireError (dropped and
counted by the receiver), never another exception, and the valid edges accepted."""

from __future__ import annotations

from typing import Any

import msgpack
import pytest

from reconswarm.net.wire import wire
from reconswarm.net.wire.keys import WireError
from reconswarm.scenario.wire_limits import MAX_AGENT_ID


def pack(**fields: Any) -> bytes:
    return msgpack.packb({"v": wire.VERSION, **fields})


def test_a_command_claiming_another_agent_on_an_agents_key_is_refused() -> None:
    payload = pack(id=4, k=1, v_mps=1.0, omega_radps=0.0)
    assert wire.cmd_from_wire(payload, 4) == wire.Cmd(4, 1, 1.0, 0.0)
    with pytest.raises(WireError, match="claims agent 4 on agent 2's key"):
        wire.cmd_from_wire(payload, 2)


def _beacon(**extra: Any) -> dict[str, Any]:
    return {"id": 3, "k": 5, "t": 0.25, "px": 1.0, "py": 2.0, "radius": 2.5, **extra}


def test_a_beacon_revision_is_optional_zero_and_at_most_2_to_the_53() -> None:
    assert wire.beacon_from_wire(pack(**_beacon()), 3).rev == 0  # senders before revisions: rev 0
    assert wire.beacon_from_wire(pack(**_beacon(rev=2**53)), 3).rev == 2**53
    for bad in (2**53 + 1, -1, 1.5, None):
        with pytest.raises(WireError, match="'rev'"):
            wire.beacon_from_wire(pack(**_beacon(rev=bad)), 3)


def _truth(ids: Any, n: int | None = None) -> bytes:
    n = len(ids) if n is None else n
    cols = {c: [0.0] * n for c in ("x", "y", "theta", "px", "py")}
    return pack(k=1, t=0.05, ids=ids, **cols)


def test_truth_ids_are_a_list_of_agent_ids_within_range() -> None:
    assert wire.truth_from_wire(_truth([0, MAX_AGENT_ID])).ids == (0, MAX_AGENT_ID)
    for ids, n in ((5, 0), ("ab", 2), ({"a": 1}, 1)):
        with pytest.raises(WireError, match="'ids'"):
            wire.truth_from_wire(_truth(ids, n))
    for bad in (MAX_AGENT_ID + 1, -1):
        with pytest.raises(WireError, match="out of range"):
            wire.truth_from_wire(_truth([1, bad]))


def _event(**fields: Any) -> bytes:
    return pack(**{"t": 1.0, "kind": "split", "before": [[1, 2, 3]], "after": [[1], [2, 3]], **fields})


def test_an_event_decodes_as_recorded_with_agent_ids_from_0_to_the_bound() -> None:
    e = wire.event_from_wire(_event())
    assert (e.kind.value, e.before, e.after) == ("split", ((1, 2, 3),), ((1,), (2, 3)))
    lost = wire.event_from_wire(_event(kind="agent_lost", before=[[0, MAX_AGENT_ID]], after=[[MAX_AGENT_ID]],
                                       agent=0))
    assert lost.agent == 0 and lost.before == ((0, MAX_AGENT_ID),)
    assert wire.event_from_wire(_event(kind="agent_lost", agent=MAX_AGENT_ID)).agent == MAX_AGENT_ID


@pytest.mark.parametrize("fields, why", [
    ({"before": "x"}, "'before'"), ({"after": 5}, "'after'"), ({"before": [1, 2]}, "'before'"),
    ({"after": [[1], "2"]}, "'after'"), ({"after": None}, "'after'"),
    ({"before": [[1, -1]]}, "out of range"), ({"after": [[MAX_AGENT_ID + 1]]}, "out of range"),
    ({"after": [[1.5]]}, "integer"),
    ({"kind": "agent_lost", "agent": -1}, "out of range"), ({"kind": "agent_lost", "agent": MAX_AGENT_ID + 1},
                                                           "out of range"),
    ({"kind": "agent_lost", "agent": "3"}, "integer"), ({"kind": ""}, "'kind'"), ({"kind": 7}, "'kind'"),
])
def test_a_malformed_event_is_a_wire_error(fields: dict[str, Any], why: str) -> None:
    with pytest.raises(WireError, match=why):
        wire.event_from_wire(_event(**fields))


def test_an_event_without_groups_has_none() -> None:
    e = wire.event_from_wire(pack(t=2.0, kind="world_stalled", duration_s=1.5))
    assert (e.before, e.after) == ((), ())
