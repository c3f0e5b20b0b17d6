"""Whatever a sample's key and payload, every role's decode path drops and counts it or hands its node a
message, and the node takes it: nothing else comes out (issue 51: a key `alive/agent/²` raised ValueError out of
the parser and stopped the world, the monitor and both agent hosts); and a message in an agent's name comes on
that agent's own key (`alive/agent/03` is another key than agent 3's: its DELETE said agent 3 left).

Keys are drawn around the run's own shapes (agent, cell, liveliness and report keys with ids such as `²`, `٣`,
`03`, `` and 2^31; cells such as `01_0`) and at random; payloads are random bytes, msgpack maps of the wire's
field names with values of any type, and well-formed messages. The ports are the processes' own, on one zenoh
session alone on 127.0.0.1."""

from __future__ import annotations

import itertools
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgpack
import pytest
import zenoh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from agent.host import ALL, AgentHost
from agent.hosted import HostedAgent
from agent.node import AgentNode
from agent.robot_io import STATES
from monitor.node import MonitorNode
from monitor.process import MonitorAdapter
from reconswarm.net.node import Invalid, Role, Token
from reconswarm.net.runtime.inbox import Inbox, Item, Rejections
from reconswarm.net.runtime.session import ZenohOptions
from reconswarm.net.trust.gate import Gate
from reconswarm.net.wire import wire
from reconswarm.net.wire.batch import FIELDS as BATCH_FIELDS
from reconswarm.net.wire.batch import batch_to_wire
from reconswarm.net.wire.hostwire import cmds_to_wire, state_batches
from reconswarm.net.wire.keys import Keys, ParsedKey, WireError
from reconswarm.net.wire.report import Report, report_to_wire
from reconswarm.record.store import RunWriter
from reconswarm.scenario.model import load
from reconswarm.scenario.wire_limits import MAX_AGENT_ID
from simworld.process import WorldAdapter
from simworld.world import Command, WorldNode
from tests.support import PAPER, free_port

S = load(PAPER)
RUN = "fuzz"
KEYS = Keys(RUN)
HOSTED = (1, 2)
IDS_TEXT = st.one_of(
    st.sampled_from(["0", "1", "2", "3", "9", "03", "00", "²", "٣", "١", "０", "+3", "-1", "-0", "", " 3",
                     str(MAX_AGENT_ID), str(MAX_AGENT_ID + 1), "9" * 11]),
    st.integers(min_value=0, max_value=12).map(str), st.text(max_size=12))
CHUNKS = st.one_of(st.sampled_from(["0_0", "-1_0", "01_0", "-0_0", "²_1", "1_2_3", "", "0_٣"]),
                   st.tuples(st.integers(-3, 3), st.integers(-3, 3)).map(lambda c: f"{c[0]}_{c[1]}"),
                   st.text(max_size=10))
MEMBERS = st.one_of(st.sampled_from(["1", "1-2", "1,2", "1-5,9", "1-1", "2,1", "1-2,3", "01", "1-", "-2", "1,,2",
                                      "3-1", "1-3,2", ""]), st.text(max_size=10))
LEAVES = st.one_of(st.sampled_from(["state", "scan", "cmd", "beacon", "beacons", "obstacles", "x", ""]),
                   st.text(max_size=8))
SUFFIXES = st.one_of(
    st.builds(lambda i, leaf: f"agent/{i}/{leaf}", IDS_TEXT, LEAVES),
    st.builds(lambda c, i, leaf: f"cell/{c}/agent/{i}/{leaf}", CHUNKS, IDS_TEXT, LEAVES),
    st.builds(lambda c, i, leaf: f"cell/{c}/host/{i}/{leaf}", CHUNKS, IDS_TEXT, LEAVES),
    st.builds(lambda c, i: f"cell/{c}/host/{i}/beacons", CHUNKS, IDS_TEXT),
    st.builds(lambda i, leaf: f"host/{i}/{leaf}", IDS_TEXT, st.one_of(st.sampled_from(["state", "cmd"]), LEAVES)),
    st.builds(lambda i, m: f"alive/host/{i}/{m}", IDS_TEXT, MEMBERS),
    IDS_TEXT.map(lambda i: f"alive/agent/{i}"),
    IDS_TEXT.map(lambda i: f"report/agent-{i}"),
    st.sampled_from(["clock", "truth", "event", "alive/simworld", "alive/monitor", "alive/x", "report/simworld"]),
    st.text(max_size=40))
KEYS_ANY = st.one_of(SUFFIXES.map(lambda s: f"swarm/{RUN}/{s}"), st.text(max_size=40))

FIELDS = ["id", "k", "t", "x", "y", "theta", "px", "py", "radius", "rev", "v_mps", "omega_radps", "alive", "mode",
          "speed", "end", "reason", "rejected", "stats", "ids", "obstacles", "points", "bodies", "process", "rows",
          "guessed_k", "scan"]
VALUES = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(min_value=-(2**63), max_value=2**64 - 1), st.floats(),
              st.text(max_size=8), st.binary(max_size=8)),
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=4), inner, max_size=4)),
    max_leaves=8)
AIDS = st.one_of(st.sampled_from([a.id for a in S.agents]), st.integers(0, MAX_AGENT_ID))
F = st.floats(-1e3, 1e3)
K = st.integers(0, 50)
MESSAGES = st.one_of(
    st.builds(lambda a, k, x, y, r: wire.beacon_to_wire(wire.Beacon(a, k, k * 0.05, x, y, r)), AIDS, K, F, F,
              st.floats(0.1, 5.0)),
    st.builds(lambda a, k, v, w: wire.cmd_to_wire(wire.Cmd(a, k, v, w)), AIDS, K, F, F),
    st.builds(lambda a, k, x, y: wire.state_to_wire(wire.State(a, k, k * 0.05, x, y, 0.0, x, y)), AIDS, K, F, F),
    st.builds(lambda a, k, r: wire.obstacles_to_wire(wire.ObstacleSet(a, k, r, {"o": ((0.0, 0.0), (1.0, 0.0),
                                                                                      (0.0, 1.0))})), AIDS, K, K),
    st.builds(lambda k, alive, end: wire.clock_to_wire(wire.Clock(k, k * 0.05, tuple(alive), end=end,
                                                                  reason="converged" if end else "")),
              K, st.lists(AIDS, max_size=12, unique=True), st.booleans()),
    st.builds(lambda a, n: report_to_wire(Report(f"agent-{a}", None, n)), IDS_TEXT, K),
)
ROWS = st.lists(st.tuples(AIDS, K, F, F, st.floats(0.1, 5.0)), min_size=1, max_size=4)
BATCHES = st.one_of(  # a host's batch of beacons: well formed (its ids maybe another host's), or any columns
    st.builds(lambda h, rows: batch_to_wire(h, [wire.Beacon(a, k, k * 0.05, x, y, r) for a, k, x, y, r in rows]),
              AIDS, ROWS),
    st.dictionaries(st.sampled_from(["host", "n", "rows", *BATCH_FIELDS]),
                    st.one_of(VALUES, st.binary(max_size=120)), max_size=10).map(
        lambda d: msgpack.packb({"v": wire.VERSION, **d}, use_bin_type=True)))
STATE_ROWS = st.lists(st.tuples(AIDS, F, F), min_size=1, max_size=4)
HOST_BATCHES = st.one_of(  # a host's states or commands: well formed (its ids maybe another host's), or any fields
    st.builds(lambda h, k, rows: state_batches(h, [wire.State(a, k, k * 0.05, x, y, 0.0, x, y,
                                                              wire.Scan(a, k, k * 0.05, ((x, y, "o"),)))
                                                   for a, x, y in rows])[0][0], AIDS, K, STATE_ROWS),
    st.builds(lambda h, k, rows: cmds_to_wire(h, [wire.Cmd(a, k, x, y) for a, x, y in rows]), AIDS, K, STATE_ROWS),
    st.dictionaries(st.sampled_from(["host", "n", "rows", "k", "t", "scans"]),
                    st.one_of(VALUES, st.binary(max_size=120), st.lists(st.lists(VALUES, max_size=3), max_size=3)),
                    max_size=8).map(lambda d: msgpack.packb({"v": wire.VERSION, **d}, use_bin_type=True)))
PAYLOADS = st.one_of(st.binary(max_size=64), MESSAGES, BATCHES, HOST_BATCHES,
                     st.dictionaries(st.sampled_from(FIELDS), VALUES, max_size=10).map(
                         lambda d: msgpack.packb({"v": wire.VERSION, **d}, use_bin_type=True)))
SAMPLES = st.tuples(KEYS_ANY, PAYLOADS, st.sampled_from(["PUT", "DELETE"]), st.sampled_from(["s1", "s2", ""]))


@dataclass
class View:
    """The live view's part LiveFeed uses (its server is the SDK's, not under test)."""

    index: dict[int, int] = field(default_factory=lambda: {a.id: i for i, a in enumerate(S.agents)})
    sets: list[wire.ObstacleSet] = field(default_factory=list)

    def obstacle_set(self, m: wire.ObstacleSet) -> None:
        self.sets.append(m)

    def close(self) -> None:
        pass


@dataclass
class Roles:
    world: WorldAdapter
    world_node: WorldNode
    monitor: MonitorAdapter
    monitor_node: MonitorNode
    live: MonitorAdapter  # a monitor that serves the live view: its obstacle sets through the same port
    live_node: MonitorNode
    host: AgentHost
    nodes: dict[int, AgentNode]
    clock: Iterator[float]


@pytest.fixture(scope="module")
def roles(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Roles]:
    z = zenoh.open(ZenohOptions((), (f"tcp/127.0.0.1:{free_port()}",), "peer").config())  # alone
    db: Path = tmp_path_factory.mktemp("fuzz") / "run.db"
    writer = RunWriter(db, S, "lockstep")
    t0 = time.monotonic()
    world_node = WorldNode(S)
    world = WorldAdapter(world_node, RUN, z)
    monitor = MonitorAdapter(S, RUN, z, writer, None)
    zid = str(z.info.zid())
    nodes = {a: AgentNode(S, a, t0) for a in HOSTED}
    links = {a: HostedAgent(nodes[a], KEYS, z, Rejections(f"agent {a}"), Gate(S, f"agent-{a}"), None, zid)
             for a in HOSTED}
    host = AgentHost(z, KEYS, links, Inbox(ordered=True))
    live = MonitorAdapter(S, RUN, z, writer, None)
    live.serve(View())  # type: ignore[arg-type]
    try:
        yield Roles(world, world_node, monitor, MonitorNode(S), live, MonitorNode(S), host, nodes,
                    itertools.count(t0, 0.01))
    finally:
        live.close()
        host.close()
        monitor.close()
        world.close()
        writer.close()
        z.close()


def _parsed(key: str) -> ParsedKey | None:
    try:
        return KEYS.parsed(key)
    except WireError:
        return None


def _counted(before: int, after: int, got: list[Any]) -> None:
    invalid = sum(isinstance(m, Invalid) for m in got)
    assert after - before >= invalid, f"{invalid} invalid, {after - before} counted"


def _own_keys(got: list[Any], items: list[Item]) -> None:
    """A message in an agent's name came on a key of that agent's, written as the run writes it (`alive/agent/03`
    or `٣` is no key of agent 3's); a beacon, state or command in a host's batch, under a host key written so, of
    an id no higher (a command: of a host the world heard the token of, naming it)."""
    keys = {it[0] for it in items}
    hosts = [p.agent_id for k in keys if (p := _parsed(k)) is not None and p.kind == "host"]
    for m in got:
        if isinstance(m, Token) and m.role is Role.AGENT:  # (the world holds one until a host's token names it)
            assert m.agent is not None, m
            named = [p for k in keys if (p := _parsed(k)) is not None and p.leaf == "host" and p.kind == "alive"]
            assert KEYS.alive_agent(m.agent) in keys or any(m.agent in (p.members or ()) for p in named), (m, keys)
        elif isinstance(m, Command):
            assert any(h is not None and h <= m.cmd.id for h in hosts), (m, keys)
            assert any(KEYS.host(h, "cmd") in keys for h in (hosts or [])), (m, keys)
        elif isinstance(m, wire.Beacon | wire.State):
            assert any(h is not None and h <= m.id for h in hosts), (m, keys)
        elif isinstance(m, (wire.Beacon, wire.ObstacleSet, wire.State, wire.Scan, wire.Cmd)):
            assert any(k.startswith(f"{KEYS.prefix}/") and f"/agent/{m.id}/" in k for k in keys), (m, keys)


@settings(max_examples=600, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                  HealthCheck.too_slow])
@given(st.lists(SAMPLES, min_size=1, max_size=6))
def test_any_key_and_payload_is_dropped_and_counted_or_taken_by_every_role(roles: Roles, samples: list) -> None:
    now = next(roles.clock)
    items: list[Item] = [(key, payload, kind, source, now) for key, payload, kind, source in samples]
    # the world
    before = roles.world.rej.count
    got_w = roles.world.route([(None, it) for it in items], now)[0]
    _counted(before, roles.world.rej.count, got_w)
    _own_keys(got_w, items)
    roles.world_node.step(got_w, now)
    # the monitor and its live view
    before = roles.monitor.rej.count
    got_m = [m for m in (roles.monitor.decode(*it) for it in items) if m is not None]
    _counted(before, roles.monitor.rej.count, got_m)
    _own_keys(got_m, items)
    roles.monitor_node.step(got_m, now)
    before = roles.live.rej.count
    got_v = roles.live.route([(None, it) for it in items], now)[0]
    _counted(before, roles.live.rej.count, got_v)
    _own_keys(got_v, items)
    roles.live_node.step(got_v, now)
    # an agent host of two agents: each sample through every subscription it may come through
    links = roles.host.active
    before = sum(lk.rej.count for lk in links.values())
    tagged = [(tag, it) for it in items for tag in (ALL, ("own", 1), ("cell", None), ("cell", (0, 0)), STATES)]
    batches = roles.host.route(tagged, now)
    got_a = [m for b in batches.values() for m in b]
    assert sum(lk.rej.count for lk in links.values()) - before >= sum(isinstance(m, Invalid) for m in got_a)
    _own_keys(got_a, items)
    for aid, batch in batches.items():
        roles.nodes[aid].step(batch, now)
