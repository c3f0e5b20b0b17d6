"""Secure mode (`run_local.sh --secure`): mutual TLS, per-process credentials, access control.

The mission completes in secure mode; while a secure run goes on, anonymous sessions get nothing, a valid
certificate the ACL does not name gets nothing, and a session holding agent 3's credentials cannot deliver
anything on agent 5's keys (beacon, cmd, obstacle set, liveliness token) nor read agent 5's state, while
agent 3's own keys do work with the same credentials.
"""

from __future__ import annotations

import json
import signal
import stat
import subprocess
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import zenoh
from zenoh import ext

from reconswarm.net.wire import wire
from reconswarm.net.wire.batch import batch_to_wire
from reconswarm.net.wire.hostwire import cmds_to_wire
from reconswarm.scenario.model import load
from reconswarm_bringup import secure
from tests.support import (
    PAPER,
    ROOT,
    assert_all_gone,
    free_port,
    launcher_cmd,
    read_run_id,
    reconswarm,
    run_launcher,
    short_paper,
    wait_for_ticks,
    wait_until,
)

SETTLE_S = 1.5  # declarations reaching the router and the other sessions


# --- helpers ---------------------------------------------------------------------------------------------

@dataclass
class Catch:
    """Samples received by a callback: (key, payload bytes, kind)."""

    items: list[tuple[str, bytes, str]] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def __call__(self, sample: Any) -> None:
        with self.lock:
            self.items.append((str(sample.key_expr), sample.payload.to_bytes(), str(sample.kind)))

    def key_set(self) -> set[str]:
        with self.lock:
            return {k for k, _, _ in self.items}

    def payloads(self, key: str) -> list[bytes]:
        with self.lock:
            return [p for k, p, _ in self.items if k == key]

    def __len__(self) -> int:
        with self.lock:
            return len(self.items)


def _open(path: Path) -> Any:
    return zenoh.open(zenoh.Config.from_file(str(path)))


def _anonymous_config(endpoint: str, **tls: Any) -> Any:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("connect/timeout_ms", '{"router": -1, "peer": -1, "client": 3000}')
    for k, v in tls.items():
        conf.insert_json5(f"transport/link/tls/{k}", json.dumps(v))
    return conf


def _mode(p: Path) -> int:
    return stat.S_IMODE(p.stat().st_mode)


# --- without a mission: what create() writes -------------------------------------------------------------

def test_create_writes_private_credentials_and_configs(tmp_path: Path) -> None:
    s = load(PAPER)
    d = tmp_path / "secrets"
    d.mkdir(mode=0o755)
    (d / "agent-99.json5").write_text("{}")  # a stale file from an earlier run with more agents
    sec = secure.create(d, s, "tcp/127.0.0.1:7447", "paper-0a1b2c")
    run = "swarm/paper-0a1b2c"  # the ACL names the run id's keys, not the scenario name's
    assert sec.endpoint == "tls/127.0.0.1:7447"
    assert _mode(d) == 0o700
    files = sorted(d.iterdir())
    assert files and all(_mode(f) == 0o600 for f in files)
    assert not (d / "agent-99.json5").exists()
    assert not any("ca-key" in f.name for f in files)  # the CA's key never touches the disk
    ids = [a.id for a in s.agents]
    documented = [sec.config_for("monitor", "-"), sec.config_for("simworld", "-"),
                  *(sec.config_for("agent", str(i)) for i in ids)]
    assert [p.name for p in documented] == ["monitor.json5", "simworld.json5", *(f"agent-{i}.json5" for i in ids)]
    for p in [*documented, d / "observer.json5", d / "intruder.json5", sec.router_config]:
        zenoh.Config.from_file(str(p))  # opens as is
    assert sec.observer_options().config_file == d / "observer.json5"
    client = json.loads((d / "agent-3.json5").read_text())
    assert client["connect"]["endpoints"] == ["tls/127.0.0.1:7447"]
    assert client["transport"]["link"]["tls"]["connect_certificate"] == str(d / "agent-3-cert.pem")
    router = json.loads(sec.router_config.read_text())
    assert router["listen"]["endpoints"] == ["tls/127.0.0.1:7447"]
    assert router["transport"]["link"]["tls"]["enable_mtls"] is True
    acl = router["access_control"]
    assert acl["enabled"] and acl["default_permission"] == "deny"
    rules = {r["id"]: r for r in acl["rules"]}
    (pol3,) = [p for p in acl["policies"] if p["subjects"] == ["agent-3"]]
    sent = {k for rid in pol3["rules"] for k in rules[rid]["key_exprs"]
            if "ingress" in rules[rid]["flows"] and set(rules[rid]["messages"]) & {"put", "reply", "liveliness_token"}}
    assert sent == {f"{run}/host/3/cmd", f"{run}/cell/*/host/3/beacons", f"{run}/cell/*/agent/3/obstacles",
                    f"{run}/report/agent-3", f"{run}/alive/agent/3", f"{run}/alive/host/3/3"}
    assert "intruder" not in {c for sub in acl["subjects"] for c in sub["cert_common_names"]}
    with pytest.raises(Exception, match="no credentials for agent 42"):
        sec.config_for("agent", "42")
    with pytest.raises(Exception, match="tcp/HOST:PORT"):
        secure.create(tmp_path / "x", s, "udp/127.0.0.1:7447")


# --- 1. the mission, secure -----------------------------------------------------------------------------

def test_secure_mission_completes(tmp_path: Path) -> None:
    """The paper's first leg (tests.support.short_paper), secure, converges when `reconswarm sim` does."""
    out = tmp_path / "run"
    scen = short_paper(tmp_path)
    t0 = time.monotonic()
    try:
        p = run_launcher(out, "-s", str(scen), "--secure", "--json")
    finally:
        assert_all_gone(out)
    wall = time.monotonic() - t0
    assert p.returncode == 0, p.stderr[-3000:]
    s = json.loads(p.stdout)
    assert s["converged"] and s["collisions"] == 0 and s["agents_lost"] == [] and s["messages_rejected"] == 0
    ref = reconswarm("sim", str(scen), "-o", str(tmp_path / "sim"), "--json")
    assert ref.returncode == 0, ref.stderr
    assert s["convergence_time_s"] == json.loads(ref.stdout)["convergence_time_s"]  # TLS + ACL change nothing
    d = out / "secrets"
    assert _mode(d) == 0o700 and all(_mode(f) == 0o600 for f in d.iterdir())
    ids = [a.id for a in load(PAPER).agents]
    for name in ["monitor", "simworld", *(f"agent-{i}" for i in ids), "observer", "intruder", "router-A"]:
        zenoh.Config.from_file(str(d / f"{name}.json5"))
    print(f"secure mission (the paper's first leg): {wall:.1f} s wall, converged at {s['convergence_time_s']} s")


# --- 2 and 3: against one live secure run ---------------------------------------------------------------

@dataclass
class Live:
    out: Path
    port: int
    proc: subprocess.Popen[bytes]

    @property
    def secrets(self) -> Path:
        return self.out / "secrets"

    @property
    def tls(self) -> str:
        return f"tls/127.0.0.1:{self.port}"

    @property
    def prefix(self) -> str:
        """`swarm/<run id>`: this launch's keys (OUTDIR/run_id)."""
        return f"swarm/{read_run_id(self.out)}"


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Live]:
    out = tmp_path_factory.mktemp("secure") / "run"
    port = free_port()
    err = out.parent / "launcher.err"  # a file, not a pipe nobody reads while the run goes on
    with err.open("wb") as fh:
        proc = subprocess.Popen(launcher_cmd(out, "--secure", port=port), cwd=ROOT, stdout=subprocess.DEVNULL,
                                stderr=fh)
    try:
        wait_for_ticks(out / "run.db", 20, proc, 120,
                       lambda: f"the secure run did not start (exit {proc.poll()}): {err.read_text()[-2000:]}")
        yield Live(out, port, proc)
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        assert_all_gone(out)


def test_anonymous_sessions_receive_nothing(live: Live) -> None:
    run = live.prefix
    # A trusted session shows that the run is publishing while the others listen.
    trusted = _open(live.secrets / "monitor.json5")
    clock = Catch()
    trusted.declare_subscriber(f"{run}/clock", clock)
    attempts = {
        "tls, no certificate": _anonymous_config(live.tls),
        "tls, the run's CA but no client certificate": _anonymous_config(
            live.tls, root_ca_certificate=str(live.secrets / "ca.pem"), enable_mtls=True),
        "tcp on the same port": _anonymous_config(f"tcp/127.0.0.1:{live.port}"),
    }
    outcome: dict[str, str] = {}
    received: dict[str, int] = {}
    try:
        for what, conf in attempts.items():
            try:
                z = zenoh.open(conf)
            except Exception as exc:  # the TLS handshake is refused: blocked before any zenoh message
                outcome[what] = f"refused: {exc}".splitlines()[0][:120]
                received[what] = 0
                continue
            got = Catch()
            z.declare_subscriber("swarm/**", got)
            z.liveliness().declare_subscriber("swarm/**", got, history=True)
            time.sleep(3.0)
            z.close()
            outcome[what] = "opened"
            received[what] = len(got)
        # A certificate of the CA that no ACL subject names: connects, and gets nothing either.
        intruder = _open(live.secrets / "intruder.json5")
        got = Catch()
        intruder.declare_subscriber("swarm/**", got)
        intruder.declare_subscriber(f"{run}/clock", got)
        intruder.liveliness().declare_subscriber(f"{run}/alive/**", got, history=True)
        time.sleep(3.0)
        tokens = list(intruder.liveliness().get(f"{run}/alive/**", timeout=2.0))
        intruder.close()
        received["intruder (CA-signed, no grant)"] = len(got) + sum(1 for r in tokens if r.ok is not None)
    finally:
        trusted.close()
    print("anonymous sessions:", outcome, "received:", received)
    assert len(clock) > 10, "the run was not publishing while the anonymous sessions listened"
    assert all(n == 0 for n in received.values()), received
    # What zenoh does with them on a mutual-TLS listener: the handshake fails, the session never opens.
    assert all(o.startswith("refused") for o in outcome.values()), outcome


def test_agent_credentials_cannot_impersonate_another_agent(live: Live) -> None:
    run = live.prefix
    sec = live.secrets
    observers = [_open(sec / "monitor.json5"), _open(sec / "simworld.json5"), _open(sec / "agent-2.json5")]
    mon, sim, a2 = observers
    beacons, cmds, sets, alive, clock, reads = Catch(), Catch(), Catch(), Catch(), Catch(), Catch()
    a3 = _open(sec / "agent-3.json5")
    try:
        a2.declare_subscriber(f"{run}/cell/*/host/*/beacons", beacons)  # (the monitor no longer hears beacons)
        mon.declare_subscriber(f"{run}/clock", clock)
        mon.liveliness().declare_subscriber(f"{run}/alive/**", alive, history=True)
        sim.declare_subscriber(f"{run}/host/*/cmd", cmds)
        a3.declare_subscriber(f"{run}/host/5/state", reads)  # not agent 3's to read
        a3.declare_subscriber(f"{run}/host/3/state", reads)  # its own (a lone agent is a host of one): allowed
        # Agent 3's credentials, agent 5's keys: beacons (its host's batch key), command, obstacle set (an advanced
        # publisher whose cache answers late joiners), liveliness token; and a token for an agent that does not exist.
        one = ext.CacheConfig(max_samples=1)
        fake_set = ext.declare_advanced_publisher(a3, f"{run}/cell/0_0/agent/5/obstacles", cache=one)
        own_set = ext.declare_advanced_publisher(a3, f"{run}/cell/0_0/agent/3/obstacles", cache=one)
        tokens = [a3.liveliness().declare_token(f"{run}/alive/agent/5"),
                  a3.liveliness().declare_token(f"{run}/alive/agent/11")]
        # The declarations are in place once the run is heard and probes on agent 3's own keys come through.
        wait_until(lambda: len(clock) and f"{run}/host/3/state" in reads.key_set(), 30,
                   "the clock and agent 3's state heard")
        probes = {f"{run}/cell/0_0/host/3/beacons": (batch_to_wire(3, [wire.Beacon(3, 0, 0.0, -78.0, 0.0, 2.6)]),
                                                     beacons),
                  f"{run}/host/3/cmd": (cmds_to_wire(3, [wire.Cmd(3, 1, 0.0, 0.0)]), cmds)}  # (not the controls)
        for key, (probe, catch) in probes.items():
            def heard(key: str = key, probe: bytes = probe, catch: Catch = catch) -> bool:
                a3.put(key, probe)
                return probe in catch.payloads(key)

            wait_until(heard, 30, f"a probe on {key} heard", every_s=0.2)
        k = wire.clock_from_wire(clock.items[-1][1]).k if len(clock) else 0
        sent: dict[str, list[bytes]] = {}

        def send(key: str, payload: bytes, publisher: Any = None) -> None:
            if publisher is not None:
                publisher.put(payload)
            else:
                a3.put(key, payload)
            sent.setdefault(key, []).append(payload)

        for n in range(20):  # valid-looking messages for the ticks to come
            send(f"{run}/cell/0_0/host/5/beacons", batch_to_wire(5, [wire.Beacon(5, k + n, 0.0, 123.0, 45.0, 2.6)]))
            send(f"{run}/host/5/cmd", cmds_to_wire(5, [wire.Cmd(5, k + n, 100.0, 0.0)]))
            hull: dict[str, tuple[tuple[float, float], ...]] = {"fake": ((0.0, 0.0), (10.0, 0.0), (0.0, 10.0))}
            fake = wire.obstacles_to_wire(wire.ObstacleSet(5, k + n, 99, hull))
            send(f"{run}/cell/0_0/agent/5/obstacles", fake, fake_set)
            # the control: the same session on agent 3's own keys
            send(f"{run}/cell/0_0/host/3/beacons", batch_to_wire(3, [wire.Beacon(3, 0, 0.0, -77.0, 0.0, 2.6)]))
            send(f"{run}/host/3/cmd", cmds_to_wire(3, [wire.Cmd(3, 0, 0.0, 0.0)]))
            time.sleep(0.1)
        own_payload = wire.obstacles_to_wire(wire.ObstacleSet(3, 0, 99, {"own": ((5.0, 5.0), (6.0, 5.0), (5.0, 6.0))}))
        send(f"{run}/cell/0_0/agent/3/obstacles", own_payload, own_set)
        time.sleep(0.5)
        # A late joiner with agent 2's credentials asks the publishers' caches for their obstacle sets.
        ext.declare_advanced_subscriber(a2, f"{run}/cell/*/agent/*/obstacles", sets,
                                        history=ext.HistoryConfig(detect_late_publishers=True))
        time.sleep(SETTLE_S + 1.0)
        for t in tokens:
            t.undeclare()
        time.sleep(0.5)
    finally:
        a3.close()
        for z in observers:
            z.close()
    seen = {"beacons": beacons, "cmd": cmds, "obstacles": sets}
    arrived = {key: sum(1 for x in seen[key.rsplit("/", 1)[1]].payloads(key) if x in payloads)
               for key, payloads in sent.items()}
    print("messages from agent 3's credentials that arrived, per key:", arrived)
    for key in (f"{run}/cell/0_0/host/5/beacons", f"{run}/host/5/cmd", f"{run}/cell/0_0/agent/5/obstacles"):
        assert arrived[key] == 0, f"a message from agent 3's credentials arrived on {key}"
    assert f"{run}/alive/agent/11" not in alive.key_set()
    assert [kind for key, _, kind in alive.items if key == f"{run}/alive/agent/5"] == ["SampleKind.PUT"]
    assert f"{run}/host/5/state" not in reads.key_set()
    # The same credentials do work on agent 3's own keys: nothing above passes because all is blocked.
    assert arrived[f"{run}/cell/0_0/host/3/beacons"] > 0 and arrived[f"{run}/host/3/cmd"] > 0
    assert arrived[f"{run}/cell/0_0/agent/3/obstacles"] >= 1  # through the publisher's cache, to a late joiner
    assert f"{run}/host/3/state" in reads.key_set()
    assert len(clock) > 10


def test_the_docs_example_of_joining_as_a_role_receives(live: Live) -> None:
    """docs/security.md's example, run as it is written (its paths pointed at this run): the observer's
    credentials hear the clock, agent 3's hear the beacons (the README once sent readers to subscribe to
    beacons with the monitor's credentials, which the rules deny: it received nothing, silently)."""
    doc = (ROOT / "docs" / "security.md").read_text()
    block = next(b.split("```", 1)[0] for b in doc.split("```python\n")[1:] if "observer.json5" in b)
    heard: list[str] = []
    scope: dict[str, Any] = {"print": lambda *a: heard.append(" ".join(map(str, a)))}
    assert "time.sleep(5)" in block
    code = block.replace("runs/latest", str(live.out)).replace("time.sleep(5)", f"time.sleep({SETTLE_S + 2.0})")
    exec(compile(code, "docs/security.md", "exec"), scope)  # returns: the example closes its sessions itself
    assert any(h.endswith("/clock") for h in heard), heard[:5]
    assert any(h.endswith("/beacons") for h in heard), heard[:5]


def test_secure_run_stops_on_sigint(live: Live) -> None:
    live.proc.send_signal(signal.SIGINT)
    assert live.proc.wait(timeout=30) == 130
    assert_all_gone(live.out, grace_s=3.0)
