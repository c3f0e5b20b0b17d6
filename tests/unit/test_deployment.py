"""A secure deployment (reconswarm_bringup/deployment.py, acl.py, secure.py): the file, checked field by field;
each host's router rules naming its own processes, deny by default, and the other hosts' routers granted what
crosses; the ROS 2 keys and the live view's reads when the deployment names them; what `write()` puts where."""

from __future__ import annotations

import json
import stat
import tomllib
from pathlib import Path
from typing import Any

import pytest

from reconswarm.errors import BadInput
from reconswarm.scenario.wire_limits import MAX_AGENT_ID
from reconswarm_bringup import acl, deployment, secure

GOOD = """
run = "paper"
world = "A"
monitor = "B"
agents_per_process = 2

[[host]]
name = "A"
router = "tls/192.168.1.10:7450"
agents = [1, 2, 3]

[[host]]
name = "B"
router = "tcp/robots.example:7450"
agents = [4, 5]
"""


def _dep(text: str = GOOD, **set_: Any) -> deployment.Deployment:
    data = tomllib.loads(text)
    data.update(set_)
    return deployment.parse(data, "dep.toml")


def _sent_and_heard(acl_: dict[str, Any], subject: str) -> tuple[set[str], set[str]]:
    """Keys the subject may send (put, reply, token: ingress) and receive (put: egress)."""
    rules = {r["id"]: r for r in acl_["rules"]}
    (pol,) = [p for p in acl_["policies"] if p["subjects"] == [subject]]
    sent = {k for rid in pol["rules"] for k in rules[rid]["key_exprs"] if "ingress" in rules[rid]["flows"]
            and set(rules[rid]["messages"]) & {"put", "reply", "liveliness_token"}}
    heard = {k for rid in pol["rules"] for k in rules[rid]["key_exprs"] if "egress" in rules[rid]["flows"]
             and "put" in rules[rid]["messages"]}
    return sent, heard


def test_a_good_file() -> None:
    d = _dep()
    assert d.run == "paper" and d.world_host == "A" and d.monitor_host == "B"
    assert [h.router for h in d.hosts] == ["tls/192.168.1.10:7450", "tls/robots.example:7450"]
    assert d.hosts[0].agent_processes == ((1, 2), (3,)) and d.hosts[1].agent_processes == ((4, 5),)
    assert d.ros2_domain is None and not d.live_view
    assert acl.processes(d, d.hosts[0]) == ["agents-1-2", "agent-3", "simworld", "observer"]
    assert acl.processes(d, d.hosts[1]) == ["agents-4-5", "monitor"]


@pytest.mark.parametrize(("change", "message"), [
    ({"run": "a/b"}, r"^dep\.toml: run: one key chunk"),
    ({"world": "C"}, r"^dep\.toml: world: no host named 'C' \(hosts: A, B\)$"),
    ({"agents_per_process": 0}, r"^dep\.toml: agents_per_process: must be >= 1, got 0$"),
    ({"ros2_domain": 233}, r"^dep\.toml: ros2_domain: must be <= 232, got 233$"),
    ({"live_view": "yes"}, r"^dep\.toml: live_view: expected true or false"),
    ({"colour": 1}, r"^dep\.toml: colour: unknown key$"),
    ({"host": []}, r"^dep\.toml: host: expected one \[\[host\]\] table or more$"),
    ({"run": "paper\n"}, r"^dep\.toml: run: one key chunk"),  # ('$' would match before the newline)
])
def test_a_bad_field_is_one_line_naming_it(change: dict[str, Any], message: str) -> None:
    with pytest.raises(BadInput, match=message):
        _dep(**change)


@pytest.mark.parametrize(("host_b", "message"), [
    ({"router": "udp/10.0.0.2:7450"}, r"^dep\.toml: host\[1\]\.router: expected tls/HOST:PORT"),
    ({"router": "tls/[::1]:7450"}, r"^dep\.toml: host\[1\]\.router: zenoh's TLS link cannot check"),
    ({"router": "tls/192.168.1.10:7450"}, r"^dep\.toml: host\[1\]\.router: tls/192\.168\.1\.10:7450 is also host 'A'"),
    ({"router": "tls/10.0.0.2:99999"}, r"^dep\.toml: host\[1\]\.router: port must be 1\.\.65535"),
    ({"agents": [3, 4]}, r"^dep\.toml: host\[1\]\.agents\[0\]: agent 3 is also on host 'A'$"),
    ({"agents": [4, "5"]}, r"^dep\.toml: host\[1\]\.agents\[1\]: expected an agent id"),
    ({"name": "A"}, r"^dep\.toml: host\[1\]\.name: host 'A' is named twice$"),
    ({"name": "../x"}, r"^dep\.toml: host\[1\]\.name: letters, digits"),
    ({"name": "B\n"}, r"^dep\.toml: host\[1\]\.name: letters, digits"),
    # the same socket as A's router under another name of the loopback: a duplicate
    ({"router": "tls/localhost:7450"}, r"^dep\.toml: host\[1\]\.router: tls/localhost:7450 is also host 'A'"),
    ({"router": "tls/LocalHost:7450"}, r"^dep\.toml: host\[1\]\.router: tls/LocalHost:7450 is also host 'A'"),
    ({"agents": [4, 2**62]}, r"^dep\.toml: host\[1\]\.agents\[1\]: expected an agent id \(an integer in "
                            r"\[0, \d+\], the wire's\), got 4611686018427387904$"),
    ({"agents": [MAX_AGENT_ID + 1]}, r"^dep\.toml: host\[1\]\.agents\[0\]: expected an agent id"),
    ({"cpu": 4}, r"^dep\.toml: host\[1\]\.cpu: unknown key$"),
])
def test_a_bad_host_is_one_line_naming_it(host_b: dict[str, Any], message: str) -> None:
    data = tomllib.loads(GOOD)
    if "localhost" in host_b.get("router", "").lower():  # A's router on the loopback, for the duplicates above
        data["host"][0]["router"] = "tls/127.0.0.1:7450"
    data["host"][1].update(host_b)
    with pytest.raises(BadInput, match=message):
        deployment.parse(data, "dep.toml")


def test_the_largest_agent_id_the_wire_carries_is_accepted() -> None:
    data = tomllib.loads(GOOD)
    data["host"][1]["agents"] = [4, MAX_AGENT_ID]
    assert deployment.parse(data, "dep.toml").hosts[1].agents == (4, MAX_AGENT_ID)


def test_a_missing_or_broken_file(tmp_path: Path) -> None:
    with pytest.raises(BadInput, match=r"nothere\.toml: file not found$"):
        deployment.load(tmp_path / "nothere.toml")
    (tmp_path / "bad.toml").write_text("run = \n")
    with pytest.raises(BadInput, match=r"bad\.toml: not valid TOML"):
        deployment.load(tmp_path / "bad.toml")


def test_each_router_names_its_own_processes_and_the_other_router() -> None:
    d = _dep()
    a, b = (acl.router_acl(d, h) for h in d.hosts)
    assert a["enabled"] and a["default_permission"] == "deny" and b["default_permission"] == "deny"
    names = [{c for s in x["subjects"] for c in s["cert_common_names"]} for x in (a, b)]
    assert names[0] == {"agents-1-2", "agent-3", "simworld", "observer", "router-B"}
    assert names[1] == {"agents-4-5", "monitor", "router-A"}
    r = "swarm/paper"
    sent, heard = _sent_and_heard(b, "agents-4-5")
    # A host's keys are its own host id's (4), its token names its agents (4-5), and no other host's.
    assert sent == {f"{r}/cell/*/host/4/beacons", f"{r}/host/4/cmd", f"{r}/alive/host/4/4-5"} | {
        k for i in (4, 5) for k in (f"{r}/cell/*/agent/{i}/obstacles", f"{r}/report/agent-{i}", f"{r}/alive/agent/{i}")}
    assert f"{r}/host/4/state" in heard and not {f"{r}/host/1/state", f"{r}/host/*/state"} & heard
    sent_3, heard_3 = _sent_and_heard(a, "agent-3")  # (a lone agent: a host of one)
    assert {f"{r}/host/3/cmd", f"{r}/alive/host/3/3"} <= sent_3 and f"{r}/host/3/state" in heard_3
    assert not any("/host/1/" in k or "/host/4/" in k or "alive/host/1" in k for k in sent_3 | heard_3)
    # What crosses from B into A: B's processes' own keys (agents 4 and 5, the monitor's events), not A's.
    sent_b, heard_b = _sent_and_heard(a, "router-B")
    assert {f"{r}/host/4/cmd", f"{r}/alive/host/4/4-5", f"{r}/alive/agent/5", f"{r}/event",
            f"{r}/alive/monitor"} <= sent_b
    assert not {f"{r}/host/1/cmd", f"{r}/alive/host/1/1-2", f"{r}/clock", f"{r}/truth", f"{r}/alive/simworld"} & sent_b
    # ... and what A may send B's way: the world's clock, truth and states, agents 1-3's own keys.
    assert {f"{r}/clock", f"{r}/truth", f"{r}/host/*/state", f"{r}/cell/*/host/1/beacons"} <= heard_b


def test_ros2_keys_and_live_view_granted_only_when_named() -> None:
    plain = _dep()
    d = _dep(ros2_domain=7, live_view=True)
    a, b = (acl.router_acl(d, h) for h in d.hosts)
    sent, heard = _sent_and_heard(a, "agent-3")
    assert {"7/robot_3/cmd_vel/**", "@ros2_lv/7/*/*/*/*/*/*/agent_3", "@ros2_lv/7/*/*/*/*/*/*/agent_3/**"} <= sent
    assert {"7/robot_3/odom/**", "swarm/paper/agent/3/scan"} <= heard  # (its scan: the plant's, on our key)
    assert not any("robot_1" in k or "agent_1" in k or "agent/1/" in k for k in sent | heard)
    sent_w, heard_w = _sent_and_heard(a, "simworld")
    assert {"7/robot_$*/odom/**", "swarm/paper/agent/*/scan"} <= sent_w and "7/robot_$*/cmd_vel/**" in heard_w
    assert not any("cmd_vel" in k for k in sent_w)  # the plant never speaks for an agent
    _, heard_m = _sent_and_heard(b, "monitor")
    assert "swarm/paper/cell/*/agent/*/obstacles" in heard_m  # what the live view draws
    plain_a = acl.router_acl(plain, plain.hosts[0])
    assert not any("robot_" in k or "@ros2_lv" in k for rl in plain_a["rules"] for k in rl["key_exprs"])
    _, heard_pm = _sent_and_heard(acl.router_acl(plain, plain.hosts[1]), "monitor")
    assert "swarm/paper/cell/*/agent/*/obstacles" not in heard_pm


def test_every_configuration_opens_in_zenoh(tmp_path: Path) -> None:
    """zenoh parses the rules' key expressions (`robot_*` is refused, `robot_$*` is not) and the TLS fields."""
    import zenoh

    sec = secure.write(tmp_path / "out", _dep(ros2_domain=7, live_view=True), split=True)
    files = sorted((tmp_path / "out").glob("*/*.json5"))
    assert len(files) == 2 + 6
    for p in files:
        zenoh.Config.from_file(str(p))
    assert sec.config_for("agent", "1-2").parent.name == "A"


def test_write_one_directory_per_host_with_only_its_own_keys(tmp_path: Path) -> None:
    d = _dep()
    sec = secure.write(tmp_path / "out", d, split=True, install_dir=Path("/etc/reconswarm"))
    a, b = tmp_path / "out" / "A", tmp_path / "out" / "B"
    assert {p.name for p in b.iterdir()} == {"ca.pem", *(f"{n}{s}" for n in ("router-B", "agents-4-5", "monitor")
                                                         for s in ("-cert.pem", "-key.pem", ".json5"))}
    assert not any("intruder" in p.name for p in a.iterdir())
    for p in [*a.iterdir(), *b.iterdir()]:
        assert stat.S_IMODE(p.stat().st_mode) == 0o600
    assert stat.S_IMODE(a.stat().st_mode) == 0o700
    router_b = json.loads(sec.router_config_for("B").read_text())
    assert router_b["listen"]["endpoints"] == ["tls/robots.example:7450"]
    assert router_b["connect"]["endpoints"] == ["tls/192.168.1.10:7450"]  # B's router connects to A's
    tls = router_b["transport"]["link"]["tls"]
    assert tls["enable_mtls"] and tls["connect_certificate"] == "/etc/reconswarm/router-B-cert.pem"
    assert "connect" not in json.loads(sec.router_config_for("A").read_text())
    mon = json.loads(sec.config_for("monitor").read_text())
    assert sec.config_for("monitor") == b / "monitor.json5"
    assert mon["connect"]["endpoints"] == ["tls/robots.example:7450"]  # a process reaches its own host's router
    assert mon["transport"]["link"]["tls"]["root_ca_certificate"] == "/etc/reconswarm/ca.pem"
    from cryptography import x509

    cert = x509.load_pem_x509_certificate((b / "router-B-cert.pem").read_bytes())
    sans = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert "robots.example" in sans.get_values_for_type(x509.DNSName)
