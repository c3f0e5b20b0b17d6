"""Agent hosts: which agents a process runs (`--id`, `--ids`, run_local.sh's `--agents-per-process`) and that
the world's and monitor's admission takes several agents from one session while still refusing anyone else
speaking for them."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from agent.process import parse_ids
from reconswarm.errors import BadInput
from reconswarm.net.trust.admission import Admission, IntrusionKind
from reconswarm.net.wire import wire
from reconswarm.net.wire.keys import Keys
from reconswarm.scenario.model import load
from reconswarm.scenario.wire_limits import MAX_AGENT_ID, MAX_IDS, ids_runs_text
from reconswarm_bringup import packing, secure
from tests.support import PAPER

S = load(PAPER)
KEYS = Keys("paper-0a1b2c")


def test_ids_and_ranges() -> None:
    assert parse_ids(None, "1-5,9") == (1, 2, 3, 4, 5, 9)
    assert parse_ids(["3"], None) == (3,)  # --id I alone: as always
    assert parse_ids(["3", "1", "3"], None) == (3, 1)  # repeatable, in order, once each
    assert parse_ids(["7"], "2-3, 7") == (7, 2, 3)
    assert parse_ids(None, "4-4") == (4,)
    assert parse_ids(None, f"0,{MAX_AGENT_ID}") == (0, MAX_AGENT_ID)  # the scenario loader's range, whole


@pytest.mark.parametrize("spec", ["", "1-", "-3", "a", "5-1", "1,,2", "1-2-3", "1.5", "²", "1-²", "٣", "03", "+3",
                                  "0-03", f"{MAX_AGENT_ID + 1}", f"1-{MAX_AGENT_ID + 1}", "1" * 5000])
def test_bad_ids_are_one_line_naming_the_option(spec: str) -> None:
    with pytest.raises(BadInput, match=r"^--ids: ") as e:
        parse_ids(None, spec)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("one", ["²", "٣", "03", "-1", "", f"{MAX_AGENT_ID + 1}"])
def test_bad_id_is_one_line_naming_the_option(one: str) -> None:
    with pytest.raises(BadInput, match=r"^--id: ") as e:
        parse_ids([one], None)
    assert "\n" not in str(e.value)


def test_too_many_ids_are_refused_before_a_list_is_built() -> None:
    """2^31 ids would be a list of 17 GB: counted first, refused in one line."""
    with pytest.raises(BadInput, match=rf"^--id/--ids: more than {MAX_IDS} agents"):
        parse_ids(None, f"0-{MAX_AGENT_ID}")
    with pytest.raises(BadInput, match=r"^--id/--ids: more than"):
        parse_ids(["7"], f"0-{MAX_IDS - 1}")
    assert len(parse_ids(None, f"0-{MAX_IDS - 1}")) == MAX_IDS


def test_no_agent_at_all_is_refused() -> None:
    with pytest.raises(BadInput, match=r"^--id or --ids: which agent"):
        parse_ids(None, None)


def test_ids_runs_text_round_trips() -> None:
    for ids in [(1,), (1, 2, 3, 5, 7, 8), (9, 3, 4), tuple(range(1, 101))]:
        assert parse_ids(None, ids_runs_text(ids)) == ids
    assert ids_runs_text((1, 2, 3, 5, 7, 8)) == "1-3,5,7-8"
    assert packing.agent_args((4,)) == ["--id", "4"] and packing.agent_args((4, 5)) == ["--ids", "4-5"]


@pytest.mark.parametrize("value", ["0", "-1", "x", "1.5", "", "auto5", "²"])
def test_agents_per_process_takes_a_positive_integer_or_auto(value: str) -> None:
    with pytest.raises(BadInput, match=r"^--agents-per-process: expected a positive integer or auto, got "):
        packing.parse(value)
    assert packing.parse("5") == 5 and packing.parse("auto") == packing.AUTO and packing.parse(" AUTO ") == "auto"


def test_per_process_auto_is_one_host_up_to_48_agents_then_one_per_cpu_and_any_k_is_clamped_to_n() -> None:
    assert packing.per_process("auto", 10, n_cpus=2) == 10  # the paper: one host
    assert packing.per_process("auto", 3, n_cpus=8) == 3
    assert packing.per_process("auto", 48, n_cpus=2) == 48
    assert packing.per_process("auto", 49, n_cpus=2) == 25  # two hosts (ceil)
    assert packing.per_process("auto", 101, n_cpus=2) == 51  # no more hosts than CPUs
    assert packing.per_process("auto", 400, n_cpus=2) == 200
    assert packing.per_process("auto", 100, n_cpus=8) == 34  # ceil(100 / 48) = 3 hosts, within the 8 CPUs
    assert packing.per_process("auto", 400, n_cpus=8) == 50  # 8 hosts: one per CPU
    assert packing.per_process("auto", 100, n_cpus=1) == 100
    assert packing.per_process(20, 10) == 10  # K > N: clamped
    assert packing.per_process(1, 10) == 1


def test_hosts_pack_consecutive_agents_that_reach_the_router_alike() -> None:
    ids = list(range(1, 11))
    assert packing.hosts(ids, 3, lambda a: "") == [(1, 2, 3), (4, 5, 6), (7, 8, 9), (10,)]
    assert packing.hosts(ids, 1, lambda a: "") == [(a,) for a in ids]
    # Two hosts (network namespaces): agents 6-10 reach another router; never packed with 1-5.
    assert packing.hosts(ids, 4, lambda a: a > 5) == [(1, 2, 3, 4), (5,), (6, 7, 8, 9), (10,)]


@dataclass
class _Started:
    """What start_agents asks of the launcher's Fleet: its CPUs to pin agent processes to, and each start."""

    cpus: tuple[int, ...]
    started: list[tuple[str, list[str]]] = field(default_factory=list)

    def start(self, role: str, ident: str, args: list[str], prefix: list[str], members: tuple[str, ...]) -> None:
        self.started.append((ident, args))


@pytest.mark.parametrize(("k", "cpus", "idents", "pinned"), [
    (5, (0, 1), ["1-5", "6-10"], (0, 1)),  # two hosts on two CPUs: one each
    (10, (0, 1), ["1-10"], (0, 1)),  # one host: the first CPU
    ("auto", (2, 3, 5), ["1-10"], (2, 3, 5)),
    (4, (0, 1), ["1-4", "5-8", "9-10"], (0, 1)),  # three hosts on two CPUs: in turn
    (1, (0, 1), [str(a) for a in range(1, 11)], ()),  # one process per agent: the scheduler places them
])
def test_agent_hosts_are_pinned_to_the_cpus_in_turn_and_one_agent_processes_are_free(
        k: int | str, cpus: tuple[int, ...], idents: list[str], pinned: tuple[int, ...]) -> None:
    fleet = _Started(cpus)
    packing.start_agents(fleet, S, k, lambda role, who: ([], []), ["--scenario", "s.toml"])
    assert [ident for ident, _args in fleet.started] == idents
    assert fleet.cpus == pinned


def _beacon(aid: int) -> wire.Beacon:
    x, y = S.starts[S.agent_index(aid)]
    return wire.Beacon(aid, 0, 0.0, float(x), float(y), float(S.radii[S.agent_index(aid)]))


def test_admission_takes_several_agents_from_one_session_and_refuses_others_for_them() -> None:
    adm = Admission(S)
    host, lone, intruder = "host-zid", "lone-zid", "intruder-zid"
    for aid in (1, 2, 3, 4, 5):  # one host's session speaks for agents 1-5
        assert adm.check_beacon(_beacon(aid), host, KEYS.host_beacons((0, 0), aid), now=0.0) is None
        assert adm.check_cmd(wire.Cmd(aid, 0, 0.1, 0.0), host, KEYS.host(aid, "cmd"), now=0.0, world_k=0) is None
        assert adm.check_report(aid, host, KEYS.report(f"agent-{aid}"), now=0.0) is None
    # and a lone agent beside it
    assert adm.check_beacon(_beacon(6), lone, KEYS.host_beacons((0, 0), 6), now=0.0) is None
    for aid in (1, 3, 5):  # nobody else speaks for a hosted agent while its host does
        for src in (intruder, lone):
            got = adm.check_cmd(wire.Cmd(aid, 0, 0.1, 0.0), src, KEYS.host(1, "cmd"), now=0.5, world_k=0)
            assert got is not None and got.kind == IntrusionKind.IMPERSONATION
    # ... nor does the host speak for the lone agent.
    got = adm.check_beacon(_beacon(6), host, KEYS.host_beacons((0, 0), 6), now=0.5)
    assert got is not None and got.kind == IntrusionKind.IMPERSONATION


def test_secure_mode_gives_an_agent_host_one_credential_granted_exactly_its_agents(tmp_path: Path) -> None:
    sec = secure.create(tmp_path / "secrets", S, "tcp/127.0.0.1:7447", "paper-0a1b2c", hosts=((1, 2, 3, 4, 5), (6,)))
    assert sec.config_for("agent", "1-5").name == "agents-1-5.json5"  # a host of one is a lone agent: agent-6
    assert sec.config_for("agent", "6").name == "agent-6.json5" and sec.config_for("agent", "6").exists()
    assert not (sec.dir / "agent-3.json5").exists()  # a hosted agent has no credential of its own
    client = json.loads(sec.config_for("agent", "1-5").read_text())
    assert client["transport"]["link"]["tls"]["connect_certificate"] == str(sec.dir / "agents-1-5-cert.pem")
    acl = json.loads(sec.router_config.read_text())["access_control"]
    # the same run with one process per agent: what each agent alone may send
    lone = secure.create(tmp_path / "lone", S, "tcp/127.0.0.1:7447", "paper-0a1b2c")
    lone_acl = json.loads(lone.router_config.read_text())["access_control"]

    def sent(subject: str) -> set[str]:
        a = lone_acl if subject.startswith("agent-") else acl
        rules = {r["id"]: r for r in a["rules"]}
        (pol,) = [p for p in a["policies"] if p["subjects"] == [subject]]
        return {k for rid in pol["rules"] for k in rules[rid]["key_exprs"] if "ingress" in rules[rid]["flows"]
                and set(rules[rid]["messages"]) & {"put", "reply", "liveliness_token"}}

    r = "swarm/paper-0a1b2c"
    own = {k for i in (1, 2, 3, 4, 5) for k in (
        f"{r}/cell/*/agent/{i}/obstacles", f"{r}/report/agent-{i}", f"{r}/alive/agent/{i}")}
    # (its batches of beacons and commands under its lowest id, its token naming its agents)
    assert sent("agents-1-5") == {*own, f"{r}/cell/*/host/1/beacons", f"{r}/host/1/cmd", f"{r}/alive/host/1/1-5"}
    alone = {k for i in range(1, 6) for k in (f"{r}/cell/*/host/{i}/beacons", f"{r}/host/{i}/cmd",
                                              f"{r}/alive/host/{i}/{i}")}
    assert set().union(*(sent(f"agent-{i}") for i in range(1, 6))) == {*own, *alone}
    assert not any(f"/{i}/" in k or k.endswith(f"/{i}") or k.endswith(f"-{i}") for k in sent("agents-1-5")
                   for i in range(6, 11))
    assert "agents-6" not in {c for sub in acl["subjects"] for c in sub["cert_common_names"]}


def test_the_memory_check_counts_agent_hosts_as_fewer_processes() -> None:
    from reconswarm_bringup import validate

    with pytest.raises(BadInput, match=r"^-n 400: 400 agent processes need about 25\.\d GB"):
        validate.machine_holds("-n 400", 400, 22_745.0)  # one process per agent: 64 MB each
    validate.machine_holds("-n 400", 400, 22_745.0, per_process=200)  # 2 hosts: 128 + 398 x 10 MB and the rest
    assert validate.run_memory_mb(400, per_process=200) == 2 * 64 + 398 * 10 + 62 + 86 + 50 + 60
    with pytest.raises(BadInput, match=r"^-n 9000: 9000 agents need about .* \(in 180 processes: 64 MB a process, "
                                       r"10 MB each further agent, plus simworld"):
        validate.machine_holds("-n 9000", 9000, 22_745.0, per_process=50)
