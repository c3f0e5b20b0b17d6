"""The world's side of one message per host (simworld/hosts.py, simworld/robot_io.py `KeysIO`): whom a host speaks
for, from its token; a tick's states as one message per host; a host's command batch believed for its own agents
only (a batch naming another's: one intrusion, those rows dropped). No network: a session that records."""

from __future__ import annotations

from typing import Any

from reconswarm.net.node import Role, Token
from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire import wire
from reconswarm.net.wire.hostwire import cmds_to_wire, state_batch_from_wire
from reconswarm.net.wire.keys import Keys
from reconswarm.scenario.model import load
from simworld.hosts import Hosts
from simworld.robot_io import KeysIO
from simworld.world import Command
from tests.support import PAPER

S = load(PAPER)
KEYS = Keys("wh")


def test_an_agents_host_is_the_first_present_claim_and_stays_its_last_when_every_claim_went() -> None:
    h = Hosts()
    h.token(1, (1, 2, 3), True)
    h.token(3, (3,), True)  # (a second claim on agent 3 while host 1 is there: not believed)
    assert h.speaks_for(1, 3) and not h.speaks_for(3, 3) and h.group([1, 2, 3, 4]) == {1: [1, 2, 3]}
    h.token(1, (1, 2, 3), False)  # host 1 killed: agent 3's next claim is host 3's
    assert h.speaks_for(3, 3) and h.speaks_for(1, 1) and h.group([1, 3]) == {1: [1], 3: [3]}
    h.token(3, (3,), False)
    assert h.speaks_for(3, 3)  # (every claim went: its last host kept)
    # A host restarted under the same key: its new token may come before the old one's end; it keeps its agents.
    h.token(1, (1, 2, 3), True)
    h.token(1, (1, 2, 3), True)
    h.token(1, (1, 2, 3), False)
    assert h.group([1, 2, 3]) == {1: [1, 2, 3]}
    # A host's newest token keeps the place its first took: a forger who came between does not win its agents.
    h.token(2, (2,), True)
    h.token(1, (1, 2), True)
    assert h.speaks_for(2, 2)  # (host 1's claims had all gone: host 2 came first this time)
    h.token(1, (1, 2, 3), True)
    assert h.speaks_for(2, 2) and h.speaks_for(1, 3)


class Pub:
    def __init__(self, key: str, log: list[tuple[str, bytes, Any]]) -> None:
        self.key, self.log = key, log

    def put(self, payload: bytes, attachment: Any = None) -> None:
        self.log.append((self.key, payload, attachment))

    def undeclare(self) -> None:
        pass


class Session:
    """What KeysIO declares, recorded."""

    def __init__(self) -> None:
        self.puts: list[tuple[str, bytes, Any]] = []

    def declare_publisher(self, key: str, **_kw: Any) -> Pub:
        return Pub(key, self.puts)

    def declare_subscriber(self, key: str, _handler: Any) -> Pub:
        return Pub(key, [])


def keys_io() -> tuple[KeysIO, Session, Gate]:
    z, gate = Session(), Gate(S, "simworld")
    gate.world_k = 5
    io = KeysIO(z, KEYS, [a.id for a in S.agents], gate, None)  # type: ignore[arg-type]
    for hid, members in ((1, (1, 2, 3, 4, 5)), (6, (6, 7, 8, 9, 10))):
        assert io.decode(KEYS.alive_host(members), b"", "PUT", f"host{hid}", 0.0) == []  # (the table's)
    return io, z, gate


def state(aid: int, k: int = 5) -> wire.State:
    return wire.State(aid, k, k * 0.05, 0.0, 0.0, 0.0, 0.5, 0.0)


def test_a_ticks_states_go_out_as_one_message_per_host_at_flush() -> None:
    io, z, _gate = keys_io()
    for a in (1, 2, 6, 7, 3):
        io.put_state(state(a))
    assert z.puts == []
    io.flush()
    assert [key for key, _p, _a in z.puts] == [KEYS.host(1, "state"), KEYS.host(6, "state")]
    (_k1, p1, att1), (_k6, p6, _att6) = z.puts
    assert [s.id for s in state_batch_from_wire(p1, 1).states] == [1, 2, 3] and att1 == (3).to_bytes(4, "little")
    assert [s.id for s in state_batch_from_wire(p6, 6).states] == [6, 7]
    io.flush()
    assert len(z.puts) == 2  # (nothing new: nothing put)


def test_a_hosts_commands_are_believed_for_its_own_agents_a_batch_naming_another_is_one_intrusion() -> None:
    io, _z, gate = keys_io()
    key = KEYS.host(1, "cmd")
    got = io.decode(key, cmds_to_wire(1, [wire.Cmd(1, 5, 1.0, 0.0), wire.Cmd(2, 5, 0.5, 0.0)]), "PUT", "host1", 1.0)
    assert got == [Command(wire.Cmd(1, 5, 1.0, 0.0), 1.0), Command(wire.Cmd(2, 5, 0.5, 0.0), 1.0)]
    assert gate.count == 0
    forged = cmds_to_wire(1, [wire.Cmd(3, 5, 1.0, 0.0), wire.Cmd(6, 5, 9.0, 0.0), wire.Cmd(7, 5, 9.0, 0.0)])
    got = io.decode(key, forged, "PUT", "host1", 1.0)
    assert got == [Command(wire.Cmd(3, 5, 1.0, 0.0), 1.0)]  # (agents 6 and 7 are host 6's)
    assert gate.count == 1 and set(gate.tally.rows) == {("impersonation", "host1")}
    # another session under host 1's key, for host 1's agents: each row refused by the agent's pin, as a command is
    got = io.decode(key, cmds_to_wire(1, [wire.Cmd(4, 5, 1.0, 0.0)]), "PUT", "intruder", 1.0)
    assert got == [Command(wire.Cmd(4, 5, 1.0, 0.0), 1.0)]  # (agent 4's first command pins its session)
    got = io.decode(key, cmds_to_wire(1, [wire.Cmd(1, 5, 1.0, 0.0)]), "PUT", "intruder", 1.2)
    assert got == [] and gate.count == 2
    # a host whose token the world never saw speaks for nobody
    got = io.decode(KEYS.host(11, "cmd"), cmds_to_wire(11, [wire.Cmd(11, 5, 1.0, 0.0)]), "PUT", "x", 1.0)
    assert got == [] and gate.count == 3


def test_an_agents_token_counts_for_the_world_once_a_host_speaks_for_it() -> None:
    io = KeysIO(Session(), KEYS, [a.id for a in S.agents], Gate(S, "simworld"), None)  # type: ignore[arg-type]
    up3 = Token(Role.AGENT, True, 3)
    assert io.decode(KEYS.alive_agent(3), b"", "PUT", "h", 0.0) is None  # (no host yet: held)
    assert io.decode(KEYS.alive_agent(4), b"", "PUT", "h", 0.0) is None
    assert io.decode(KEYS.alive_agent(4), b"", "DELETE", "h", 0.0) == Token(Role.AGENT, False, 4)  # (gone: not held)
    assert io.decode(KEYS.alive_host((1, 2, 3, 4)), b"", "PUT", "h", 0.0) == [up3]
    assert io.decode(KEYS.alive_agent(2), b"", "PUT", "h", 0.0) == Token(Role.AGENT, True, 2)  # (its host known)
