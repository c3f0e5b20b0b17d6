"""One message per host and tick each way (reconswarm/net/wire/hostwire.py): the world's states of a host's agents, the
host's commands; their keys and the host token's members (reconswarm/net/wire/keys.py, wire_limits.py)."""

from __future__ import annotations

import msgpack
import pytest

from reconswarm.net.node import Role, Token
from reconswarm.net.wire import wire
from reconswarm.net.wire.decode import AGENT, WORLD, decode
from reconswarm.net.wire.hostwire import (
    CMD_ROW,
    POINTS_PER_MESSAGE,
    STATE_ROW,
    cmd_batch_from_wire,
    cmds_to_wire,
    state_batch_from_wire,
    state_batches,
)
from reconswarm.net.wire.keys import Keys, WireError
from reconswarm.scenario.wire_limits import ids_from_text, ids_to_text

KEYS = Keys("hw")


def st(aid: int, k: int = 7, scan: bool = True) -> wire.State:
    t = 0.05 * k
    sc = wire.Scan(aid, k, t, ((1.5, -2.0, "diamond"), (3.0, 4.25, "o2")), ((9, 1.0, 2.0),)) if scan else None
    return wire.State(aid, k, t, 1.0 + aid, 2.0, 0.3, 1.5 + aid, 2.0, sc)


def test_a_hosts_states_and_commands_come_back_as_they_went_every_row_with_its_id() -> None:
    states = [st(3), st(4, scan=False), st(9)]
    ((payload, n),) = state_batches(3, states)
    got = state_batch_from_wire(payload, 3)
    assert n == 3 and got.host == 3 and got.states == tuple(states)
    cmds = [wire.Cmd(3, 7, 1.25, -0.5), wire.Cmd(4, 6, 0.0, 0.0), wire.Cmd(3, 8, 1.0, 0.0)]  # (ticks of their own)
    back = cmd_batch_from_wire(cmds_to_wire(3, cmds), 3)
    assert back.host == 3 and back.cmds == tuple(cmds)
    # the decode table: the agents take state batches, the world command batches and host tokens
    assert decode(KEYS, AGENT, KEYS.host(3, "state"), payload, "PUT") == got
    assert decode(KEYS, WORLD, KEYS.host(3, "state"), payload, "PUT") is None
    assert decode(KEYS, WORLD, KEYS.host(3, "cmd"), cmds_to_wire(3, cmds), "PUT") == back
    tok = decode(KEYS, WORLD, KEYS.alive_host((3, 4, 9)), b"", "DELETE")
    assert tok == Token(Role.HOST, False, 3, (3, 4, 9))
    assert decode(KEYS, AGENT, KEYS.alive_host((3,)), b"", "PUT") is None


def test_states_whose_scans_are_too_large_for_one_message_go_in_several_each_whole() -> None:
    big = tuple((float(i), 0.0, "o") for i in range(POINTS_PER_MESSAGE // 2 + 1))
    states = [wire.State(a, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, wire.Scan(a, 0, 0.0, big)) for a in (1, 2, 3)]
    out = state_batches(1, states)
    assert [n for _p, n in out] == [1, 1, 1]
    assert [s for p, _n in out for s in state_batch_from_wire(p, 1).states] == states
    assert len(state_batches(1, [st(a) for a in range(1, 200)])) == 1


def _packed(**fields: object) -> bytes:
    return msgpack.packb({"v": wire.VERSION, **fields}, use_bin_type=True)


def _state_fields(rows_: list[tuple[int, float, float, float, float, float]], **more: object) -> dict[str, object]:
    return {"host": 3, "k": 1, "t": 0.05, "n": len(rows_), "rows": b"".join(STATE_ROW.pack(*r) for r in rows_),
            "scans": [], **more}


@pytest.mark.parametrize(("fields", "why"), [
    (_state_fields([(3, 0, 0, 0, 0, 0)], host=4), "under the key of host 3"),
    (_state_fields([(3, 0, 0, 0, 0, 0)], n=2), "expected 2 packed rows"),
    (_state_fields([(3, 0, 0, 0, 0, 0), (3, 1, 1, 1, 1, 1)]), "twice"),
    (_state_fields([(2, 0, 0, 0, 0, 0)]), "below its host"),
    (_state_fields([(3, float("nan"), 0, 0, 0, 0)]), "not finite"),
    (_state_fields([(3, 0, 0, 0, 0, 0)], t=float("inf")), "not finite"),
    (_state_fields([(3, 0, 0, 0, 0, 0)], k=-1), "expected a tick"),
    (_state_fields([(3, 0, 0, 0, 0, 0)], scans=[[1, [], []]]), "each scan is"),
    (_state_fields([(3, 0, 0, 0, 0, 0), (4, 0, 0, 0, 0, 0)], scans=[[1, [], []], [0, [], []]]), "not ascending"),
    (_state_fields([(3, 0, 0, 0, 0, 0)], scans=[[0, [[0.0, float("nan"), "o"]], []]]), "not finite"),
    (_state_fields([(3, 0, 0, 0, 0, 0)], scans=[[0, [], [[1, 0.0]]]]), "each body"),
    (_state_fields([(3, 0, 0, 0, 0, 0)], n=0, rows=b""), "expected 1.."),
])
def test_a_malformed_state_batch_is_refused_saying_why(fields: dict[str, object], why: str) -> None:
    with pytest.raises(WireError, match=why):
        state_batch_from_wire(_packed(**fields), 3)


@pytest.mark.parametrize(("fields", "why"), [
    ({"host": 3, "n": 1, "rows": CMD_ROW.pack(3, 0, 1.0, 0.0)[:-1]}, "packed rows"),
    ({"host": 3, "n": 2, "rows": CMD_ROW.pack(5, 0, 1.0, 0.0) * 2}, "twice"),  # (one agent's tick twice)
    ({"host": 3, "n": 1, "rows": CMD_ROW.pack(1, 0, 1.0, 0.0)}, "below its host"),
    ({"host": 3, "n": 1, "rows": CMD_ROW.pack(3, -2, 1.0, 0.0)}, "out of range"),
    ({"host": 3, "n": 1, "rows": CMD_ROW.pack(3, 0, float("inf"), 0.0)}, "not finite"),
    ({"host": True, "n": 1, "rows": CMD_ROW.pack(3, 0, 1.0, 0.0)}, "expected an agent id"),
])
def test_a_malformed_command_batch_is_refused_saying_why(fields: dict[str, object], why: str) -> None:
    with pytest.raises(WireError, match=why):
        cmd_batch_from_wire(_packed(**fields), 3)
    with pytest.raises(WireError, match="schema version"):
        cmd_batch_from_wire(msgpack.packb({"v": 2, **fields}), 3)
    with pytest.raises(WireError, match="undecodable"):
        cmd_batch_from_wire(b"\xc1", 3)


def test_host_keys_and_the_members_of_a_host_token_are_read_only_in_their_canonical_text() -> None:
    assert ids_to_text((9, 1, 2, 3, 4, 5)) == "1-5,9" and ids_from_text("1-5,9") == (1, 2, 3, 4, 5, 9)
    assert ids_to_text([3]) == "3" and ids_from_text("3") == (3,)
    for bad in ("1-3,4-5", "5,1", "3-3", "03", "1-", "-1", "1,,2", "", "1-5,5", "²", "1-3,2"):
        assert ids_from_text(bad) is None, bad
    assert ids_from_text("1-10", most=9) is None
    p = KEYS.parsed(KEYS.alive_host((1, 2, 3, 4, 5, 9)))
    assert (p.kind, p.agent_id, p.leaf, p.members) == ("alive", 1, "host", (1, 2, 3, 4, 5, 9))
    assert KEYS.parse(KEYS.host(3, "state")) == ("host", 3, "state") and KEYS.parse(KEYS.host(3, "cmd"))[2] == "cmd"
    for bad in ("alive/host/2/1-5", "alive/host/1/1-3,4-5", "alive/host/01/1", "alive/host/1", "host/03/cmd",
                "host/3/beacons", "host/3/state/x"):
        with pytest.raises(WireError):
            KEYS.parsed(f"{KEYS.prefix}/{bad}")
