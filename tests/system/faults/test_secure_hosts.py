"""A secure deployment over two routers, as `reconswarm credentials` makes it for real machines (here both on
127.0.0.1, each router on its own port): the routers link over mutual TLS; each router admits its own
processes only; what one host's process may say crosses to the other host, what it may not is stopped at its
own router; a session without credentials is refused by either router. A bad deployment file: one line, exit 2.
"""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import zenoh

from reconswarm.net.wire.keys import Keys
from tests.support import (
    ROOT,
    assert_all_gone,
    free_port,
    reconswarm,
    router_listening,
    wait_for_ticks,
    wait_router_listening,
    wait_until,
)

from .test_secure import Catch, _anonymous_config, _open

RUN = "paper-hosts"


@dataclass
class Two:
    out: Path
    ports: tuple[int, int]

    def cfg(self, host: str, name: str) -> Path:
        return self.out / host / f"{name}.json5"


@pytest.fixture(scope="module")
def two(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Two]:
    d = tmp_path_factory.mktemp("hosts")
    pa, pb = free_port(), free_port()
    (d / "deployment.toml").write_text(f"""
run = "{RUN}"
world = "A"
monitor = "A"

[[host]]
name = "A"
router = "tls/127.0.0.1:{pa}"
agents = [1, 2, 3, 4, 5]

[[host]]
name = "B"
router = "tls/localhost:{pb}"
agents = [6, 7, 8, 9, 10]
""")
    p = reconswarm("credentials", str(d / "deployment.toml"), "-o", str(d / "creds"))
    assert p.returncode == 0, p.stderr
    print(p.stdout)
    two = Two(d / "creds", (pa, pb))
    routers = []
    for host in ("A", "B"):
        log = (d / f"router-{host}.log").open("wb")
        routers.append(subprocess.Popen([sys.executable, "-m", "reconswarm_bringup.cli", "router", "--zenoh-config",
                                         str(two.cfg(host, f"router-{host}"))], cwd=ROOT, stdout=log, stderr=log))
    try:
        wait_router_listening(pa, proc=routers[0])
        wait_until(lambda: router_listening(pb, "localhost"), 60, f"router B listening on localhost:{pb}",
                   proc=routers[1])
        yield two
    finally:
        for r in routers:
            r.terminate()
        for r in routers:
            r.wait(timeout=30)
        assert_all_gone(d)


def heard_probe(speaker: zenoh.Session, key: str, *catches: Catch, payload: bytes = b"probe") -> None:
    """Put `payload` on `key` from `speaker` every 0.2 s until each of `catches` heard it (the way is open)."""

    def heard() -> bool:
        speaker.put(key, payload)
        return all(payload in c.payloads(key) for c in catches)

    wait_until(heard, 60, f"{payload!r} on {key} heard", every_s=0.2)


def test_what_a_process_may_say_crosses_hosts_and_nothing_else(two: Two) -> None:
    """Listeners and speakers are separate sessions (a session hears its own puts whatever the routers say)."""
    keys = Keys(RUN)
    a1, a2, world = (_open(two.cfg("A", n)) for n in ("agent-1", "agent-2", "simworld"))  # host A
    b6, b7 = (_open(two.cfg("B", n)) for n in ("agent-6", "agent-7"))  # host B
    try:
        on_a, on_b = Catch(), Catch()
        a1.declare_subscriber(keys.clock, on_a)
        a1.declare_subscriber(keys.host_beacons(None, None), on_a)
        b6.declare_subscriber(keys.clock, on_b)
        b6.declare_subscriber(keys.host_beacons(None, None), on_b)
        # The declarations crossed both routers once a probe on a beacon key each way comes through (each listener
        # declared its clock subscription first: it is through too). The probes' cell (1_1) is one no check reads.
        probe7, probe2 = keys.host_beacons((1, 1), 7), keys.host_beacons((1, 1), 2)
        heard_probe(b7, probe7, on_a)
        heard_probe(a2, probe2, on_b)
        for _ in range(5):
            b7.put(keys.host_beacons((0, 0), 7), b"seven")  # its own: crosses to A
            b7.put(keys.host_beacons((0, 0), 1), b"forged")  # agent 1's, from B: stopped at B's router
            b7.put(keys.clock, b"forged clock")  # only the world (on A) may
            world.put(keys.clock, b"clock")  # crosses to B
            a2.put(keys.host_beacons((0, 0), 2), b"two")  # crosses to B
            time.sleep(0.2)  # (the pace of a round)
        # b7's forgeries went the ways its own beacons go, in order: a last probe of its own heard on both hosts
        # means they came or never will; and the world's and agent 2's five each
        heard_probe(b7, probe7, on_a, on_b, payload=b"last")
        wait_until(lambda: len(on_a.payloads(keys.clock)) >= 5 and len(on_b.payloads(keys.clock)) >= 5
                   and len(on_b.payloads(keys.host_beacons((0, 0), 2))) >= 5, 30,
                   "the world's clocks and agent 2's beacons")
        print("heard on A:", sorted(on_a.key_set()), "on B:", sorted(on_b.key_set()))
        assert on_a.payloads(keys.host_beacons((0, 0), 7)) == [b"seven"] * 5
        assert on_b.payloads(keys.host_beacons((0, 0), 2)) == [b"two"] * 5
        assert on_a.payloads(keys.clock) == on_b.payloads(keys.clock) == [b"clock"] * 5  # only the world's
        assert on_a.payloads(keys.host_beacons((0, 0), 1)) == on_b.payloads(keys.host_beacons((0, 0), 1)) == []
    finally:
        for z in (a1, a2, world, b6, b7):
            z.close()


def test_a_router_admits_only_its_own_hosts_processes(two: Two) -> None:
    """Agent 1's credential (host A's) is valid for the CA but names nothing on B's router: connected there, it
    hears nothing and says nothing."""
    keys = Keys(RUN)
    a1_conf = zenoh.Config.from_file(str(two.cfg("A", "agent-1")))
    a1_conf.insert_json5("connect/endpoints", f'["tls/localhost:{two.ports[1]}"]')
    stray, b6, b7 = zenoh.open(a1_conf), _open(two.cfg("B", "agent-6")), _open(two.cfg("B", "agent-7"))
    try:
        got_stray, got_b6 = Catch(), Catch()
        stray.declare_subscriber("swarm/**", got_stray)
        stray.declare_subscriber(keys.host_beacons(None, None), got_stray)
        b6.declare_subscriber(keys.host_beacons(None, None), got_b6)
        probe7 = keys.host_beacons((1, 1), 7)  # (a cell no check reads)
        heard_probe(b7, probe7, got_b6)  # agent 6's subscription is in place
        for _ in range(5):
            stray.put(keys.host_beacons((0, 0), 1), b"from B's router")
            b7.put(keys.host_beacons((0, 0), 7), b"seven")
            time.sleep(0.2)  # (the pace of a round)
        wait_until(lambda: len(got_b6.payloads(keys.host_beacons((0, 0), 7))) >= 5, 30,
                   "agent 7's five beacons at agent 6")
        # (the stray's last put went to the same router before agent 7's last beacon: it had as long to arrive)
        print("stray heard:", sorted(got_stray.key_set()), "agent 6 heard:", sorted(got_b6.key_set()))
        assert got_b6.payloads(keys.host_beacons((0, 0), 7)) == [b"seven"] * 5  # B works for its own
        assert got_b6.payloads(keys.host_beacons((0, 0), 1)) == []  # the stray's puts reach nobody
        # ... and nothing reaches it (a session hears its own puts locally, whatever the router says)
        assert got_stray.key_set() <= {keys.host_beacons((0, 0), 1)}
    finally:
        for z in (stray, b6, b7):
            z.close()


def test_sessions_without_credentials_are_refused_by_both_routers(two: Two) -> None:
    outcome = {}
    for host, ep in (("A", f"tls/127.0.0.1:{two.ports[0]}"), ("B", f"tls/localhost:{two.ports[1]}"),
                     ("B over tcp", f"tcp/127.0.0.1:{two.ports[1]}")):
        try:
            zenoh.open(_anonymous_config(ep)).close()
            outcome[host] = "opened"
        except Exception as exc:
            outcome[host] = f"refused: {exc}".splitlines()[0][:100]
    print(outcome)
    assert all(o.startswith("refused") for o in outcome.values()), outcome


def test_a_bad_deployment_file_is_one_line_exit_2(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('run = "x"\nworld = "A"\nmonitor = "A"\n[[host]]\nname = "A"\nrouter = "udp/10.0.0.1:7450"\n'
                   'agents = [1]\n')
    p = reconswarm("credentials", str(bad), "-o", str(tmp_path / "out"))
    assert p.returncode == 2 and p.stderr.strip().count("\n") == 0, p.stderr
    assert "bad.toml: host[0].router:" in p.stderr and not (tmp_path / "out" / "A").exists()


# --- run_local.sh --secure --hosts 2 (network namespaces: root) -----------------------------------------------

def test_secure_two_hosts_converge_through_a_partition_and_refuse_outsiders(tmp_path: Path) -> None:
    """The paper at --secure --hosts 2 with the link between the hosts cut for 4 s: the routers relink over
    mutual TLS and the mission converges as in open mode; meanwhile a session without credentials is refused by
    host A's router and the CA-signed certificate no rule names hears nothing there."""
    import json
    import signal

    from reconswarm.scenario.model import load
    from tests.support import events, launcher_cmd, paper_with, read_run_id

    from .test_partition import need_network_namespaces

    need_network_namespaces()
    out = tmp_path / "run"
    scen = paper_with(tmp_path, **{"duration_s = 300.0": "duration_s = 600.0"})  # (as the open partition test)
    err = tmp_path / "launcher.err"
    with err.open("wb") as fh:
        proc = subprocess.Popen(launcher_cmd(out, "-s", str(scen), "--secure", "--hosts", "2", "--fault",
                                             "partition@60+4", "--json"), cwd=ROOT, stdout=subprocess.PIPE, stderr=fh)
    try:
        wait_for_ticks(out / "run.db", 20, proc, 300, lambda: err.read_text()[-3000:])
        secrets = out / "secrets"
        router_a = json.loads((secrets / "router-A.json5").read_text())
        ep_a = router_a["listen"]["endpoints"][0]
        assert router_a["access_control"]["default_permission"] == "deny"
        assert json.loads((secrets / "router-B.json5").read_text())["connect"]["endpoints"] == [ep_a]
        run = f"swarm/{read_run_id(out)}"
        try:
            zenoh.open(_anonymous_config(ep_a)).close()
            anonymous = "opened"
        except Exception as exc:
            anonymous = f"refused: {exc}".splitlines()[0][:100]
        intruder, got = _open(secrets / "intruder.json5"), Catch()
        intruder.declare_subscriber(f"{run}/**", got)
        intruder.liveliness().declare_subscriber(f"{run}/alive/**", got, history=True)
        time.sleep(3.0)
        intruder.close()
        stdout, _ = proc.communicate(timeout=600)
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            proc.wait(timeout=60)
        assert_all_gone(out)
    assert proc.returncode == 0, err.read_text()[-3000:]
    s = json.loads(stdout)
    print(f"secure, two hosts, partition@60+4: converged {s['converged']} at {s['convergence_time_s']} s, "
          f"collisions {s['collisions']}, intrusions {s['intrusions']}; outsider {anonymous}; "
          f"intruder heard {len(got)}")
    assert anonymous.startswith("refused") and len(got) == 0
    assert s["converged"] and s["collisions"] == 0 and s["agents_lost"] == []
    ev = events(out / "run.db")
    net = [e for e in ev if e.get("cause") == "network"]
    assert [e["kind"] for e in net] == ["split", "merge"]
    b_agents = [a.id for a in load(scen).agents][5:]
    assert net[0]["after"] == [[1, 2, 3, 4, 5], b_agents]
    assert sorted(e["agent"] for e in ev if e["kind"] == "agent_lost") == b_agents  # B's, while cut off
