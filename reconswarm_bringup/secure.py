"""Secure mode (`run_local.sh --secure`): a CA, per-process credentials, mutual TLS and access control.

`create()` writes into OUTDIR/secrets/ (directory 0700, every file 0600):

- `ca.pem`: the run's certificate authority (its private key is never written: nobody can issue more
  credentials for this run once `create()` returns);
- `<name>-cert.pem`, `<name>-key.pem` for the router (SAN 127.0.0.1, ::1, localhost and the endpoint's
  host) and for every client: `monitor`, `simworld`, `agent-<id>`, `agents-<ids>` for each agent host of
  the run (`--agents-per-process`: one process, one session, e.g. `agents-1-5`, granted exactly what its
  agents are), `observer` (the launcher's clock watcher) and `intruder` (a valid certificate the ACL
  grants nothing: the flood fault uses it); a client certificate's common name is its ACL subject;
- `router.json5`: listens on `tls/HOST:PORT` only, requires a client certificate signed by the CA, and
  enforces the access control rules below with `default_permission: "deny"`;
- `<name>.json5`: each client's complete zenoh configuration (mode, router, TLS paths, lease,
  timestamping), which `zenoh.Config.from_file` opens as is.

The rules (`R` = `swarm/<run>`) allow, per subject and nothing else:

- agent i: put `R/agent/i/cmd`, `R/cell/*/agent/i/{beacon,obstacles}` (in any cell, under its own id
  only), its intrusion report `R/report/agent-i`; token `R/alive/agent/i`; the advanced publisher's cache
  (queryable `R/cell/*/agent/i/obstacles/@adv/pub/**`, replies on `R/cell/*/agent/i/obstacles`); subscribe
  (and receive) `R/agent/i/state`, `R/clock`, `R/cell/*/agent/*/beacon`,
  `R/cell/*/agent/*/obstacles` (one cell or all); history queries on `R/cell/*/agent/*/obstacles/@adv/**`;
  liveliness subscriptions on `R/alive/**` and `R/cell/*/agent/*/obstacles/@adv/pub/**`;
- simworld: put `R/clock`, `R/truth`, `R/agent/*/state`, `R/report/simworld`; token
  `R/alive/simworld`; subscribe `R/agent/*/cmd`, liveliness `R/alive/**`; the truth's advanced publisher
  (queryable `R/truth/@adv/pub/**` replying on `R/truth`, heartbeats put under `R/truth/@adv/pub/**`);
- monitor: put `R/event`; token `R/alive/monitor`; subscribe `R/truth`, `R/clock`, `R/report/*`, liveliness
  `R/alive/**`; recovery of a lost truth (subscribe the heartbeats `R/truth/@adv/pub/**`, query
  `R/truth/@adv/**`, receive replies on `R/truth`);
- observer: subscribe `R/clock`, `R/event`;
- intruder, or any other certificate of the CA: nothing.

Ingress rules say what a subject may send to the router, egress rules what the router may forward to
it, so a subject cannot even receive on keys it was not granted (should a peer send there).
"""

from __future__ import annotations

import datetime as _dt
import ipaddress
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from reconswarm.errors import BadInput
from reconswarm.net.session import LEASE_MS, ZenohOptions
from reconswarm.scenario import Scenario
from reconswarm_bringup.packing import ids_spec

ROLES = ("monitor", "simworld", "agent")
VALID_DAYS = 30
_ALL_FLOWS = ("ingress", "egress")


@dataclass(frozen=True)
class Secrets:
    """What `create()` wrote: the TLS endpoint and the configuration file of every participant."""

    dir: Path
    endpoint: str
    run: str
    agent_ids: tuple[int, ...]
    hosts: tuple[tuple[int, ...], ...] = ()  # agent hosts (two agents or more in one process)

    @property
    def router_config(self) -> Path:
        return self.dir / "router.json5"

    @property
    def ca(self) -> Path:
        return self.dir / "ca.pem"

    def config_for(self, role: str, ident: str = "-") -> Path:
        """The client configuration of a role: `monitor`, `simworld` or `agent` (ident = the agent id, or an agent
        host's ids, e.g. `1-5`)."""
        if role == "agent" and ident in {host_name(h).removeprefix("agents-") for h in self.hosts}:
            return self.dir / f"agents-{ident}.json5"
        if role == "agent":
            try:
                aid = int(ident)
            except ValueError:
                raise BadInput(f"secure: agent id {ident!r} is not an integer") from None
            if aid not in self.agent_ids:
                raise BadInput(f"secure: no credentials for agent {aid} (the scenario's agents: "
                               f"{', '.join(map(str, self.agent_ids))})")
            return self.dir / f"agent-{aid}.json5"
        if role in ("monitor", "simworld", "observer", "intruder"):
            return self.dir / f"{role}.json5"
        raise BadInput(f"secure: unknown role {role!r} (expected one of {', '.join(ROLES)})")

    def observer_options(self) -> ZenohOptions:
        """Zenoh options of the launcher's own watcher (may subscribe to the clock and events only)."""
        return ZenohOptions.build(None, None, "client", self.dir / "observer.json5")


def tls_endpoint(endpoint: str) -> str:
    """`tcp/HOST:PORT` (or `tls/HOST:PORT`) -> `tls/HOST:PORT`; anything else is refused."""
    proto, sep, addr = endpoint.partition("/")
    host, _, port = addr.rpartition(":")
    if not sep or proto not in ("tcp", "tls") or not host or not port.isdigit():
        raise BadInput(f"--secure: the router endpoint must be tcp/HOST:PORT, got {endpoint!r}")
    return f"tls/{addr}"


def host_name(ids: tuple[int, ...]) -> str:
    """An agent host's certificate name (its ACL subject): `agents-1-5`, `agents-1-3,5`."""
    return f"agents-{ids_spec(ids)}"


def create(secrets_dir: Path, scenario: Scenario, endpoint: str, run: str | None = None,
           hosts: tuple[tuple[int, ...], ...] = ()) -> Secrets:
    """Create the CA, every credential and configuration of one secure run under secrets_dir.

    run: the run id of the key prefix `swarm/<run>` the access rules name (default: the scenario name);
    hosts: the agents of each agent host (those of more than one agent get a credential of their own)."""
    ep = tls_endpoint(endpoint)
    host = ep.partition("/")[2].rpartition(":")[0].strip("[]")
    secrets_dir = Path(secrets_dir).resolve()
    _private_dir(secrets_dir)
    for old in secrets_dir.iterdir():  # credentials of an earlier run (another CA, other agents)
        if old.is_file() and old.suffix in (".pem", ".json5"):
            old.unlink()
    ids = tuple(a.id for a in scenario.agents)
    many = tuple(h for h in hosts if len(h) > 1)
    unknown = [a for h in many for a in h if a not in ids]
    if unknown:
        raise BadInput(f"secure: no agent {unknown[0]} in the scenario for an agent host")
    sec = Secrets(secrets_dir, ep, run or scenario.meta.name, ids, many)

    ca_key, ca_cert = _make_ca(sec.run)
    _write(sec.ca, _cert_pem(ca_cert))
    names = ["monitor", "simworld", *(f"agent-{i}" for i in ids), *map(host_name, many), "observer", "intruder"]
    _issue(secrets_dir, "router", ca_key, ca_cert, server_names=_server_names(host))
    for name in names:
        _issue(secrets_dir, name, ca_key, ca_cert)

    _write(sec.router_config, _dump(router_config(sec)))
    for name in names:
        _write(secrets_dir / f"{name}.json5", _dump(client_config(sec, name)))
    return sec


# --- configurations ------------------------------------------------------------------------------------

def _base(mode: str, tls: dict[str, Any]) -> dict[str, Any]:
    """What every configuration of a secure run shares: no multicast, timestamps, the lease, mTLS with our CA."""
    return {
        "mode": mode,
        "scouting": {"multicast": {"enabled": False}},
        "timestamping": {"enabled": True},
        "transport": {"link": {"tx": {"lease": LEASE_MS}, "tls": {**tls, "enable_mtls": True}}},
    }


def client_config(sec: Secrets, name: str) -> dict[str, Any]:
    """A complete client configuration: `zenoh.Config.from_file` opens it as is."""
    d = sec.dir
    conf = _base("client", {
        "root_ca_certificate": str(d / "ca.pem"),
        "connect_private_key": str(d / f"{name}-key.pem"),
        "connect_certificate": str(d / f"{name}-cert.pem"),
        "verify_name_on_connect": True,
    })
    conf["connect"] = {"endpoints": [sec.endpoint], "timeout_ms": {"router": -1, "peer": -1, "client": 15000}}
    return conf


def router_config(sec: Secrets) -> dict[str, Any]:
    d = sec.dir
    return {
        **_base("router", {
            "root_ca_certificate": str(d / "ca.pem"),
            "listen_private_key": str(d / "router-key.pem"),
            "listen_certificate": str(d / "router-cert.pem"),
        }),
        "listen": {"endpoints": [sec.endpoint]},
        "access_control": access_control(sec.run, sec.agent_ids, sec.hosts),
    }


def access_control(run: str, agent_ids: tuple[int, ...], hosts: tuple[tuple[int, ...], ...] = ()) -> dict[str, Any]:
    """Default deny; every subject (a certificate common name) gets exactly what its process uses (an agent
    host: what each of its agents uses)."""
    r = f"swarm/{run}"
    rules: list[dict[str, Any]] = []
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []

    def rule(rid: str, messages: list[str], flows: tuple[str, ...], keys: list[str]) -> str:
        rules.append({"id": rid, "messages": messages, "flows": list(flows), "permission": "allow",
                      "key_exprs": keys})
        return rid

    def subscribe(rid: str, keys: list[str]) -> list[str]:
        """Declare a subscriber on keys (ingress) and receive the samples published there (egress)."""
        return [rule(f"{rid}-declare", ["declare_subscriber"], ("ingress",), keys),
                rule(f"{rid}-receive", ["put"], ("egress",), keys)]

    def publish(rid: str, keys: list[str], subscribed_as: list[str] | None = None) -> list[str]:
        """Put on keys (ingress), and learn of the subscribers there (egress): a client sends a sample only
        when the router has declared a matching subscriber to it. Declarations keep the subscriber's own
        key expression (`R/agent/*/cmd`), hence subscribed_as."""
        return [rule(f"{rid}-put", ["put"], ("ingress",), keys),
                rule(f"{rid}-matching", ["declare_subscriber"], ("egress",), [*keys, *(subscribed_as or [])])]

    def membership(rid: str, token: str) -> list[str]:
        """Declare one's own liveliness token and follow everyone's (subscriber with history)."""
        return [rule(f"{rid}-token", ["liveliness_token"], ("ingress",), [token]),
                rule(f"{rid}-follow", ["declare_liveliness_subscriber"], ("ingress",), [f"{r}/alive/**"]),
                rule(f"{rid}-tokens", ["liveliness_token"], ("egress",), [f"{r}/alive/**"])]

    def grant(subject: str, rule_ids: list[str]) -> None:
        subjects.append({"id": subject, "cert_common_names": [subject]})
        policies.append({"id": f"{subject}-policy", "rules": rule_ids, "subjects": [subject]})

    # Shared by every agent: the swarm's beacons and obstacle sets, the clock, history of obstacle sets.
    obstacles, beacons = f"{r}/cell/*/agent/*/obstacles", f"{r}/cell/*/agent/*/beacon"
    agents_common = [
        *subscribe("agents-sub", [f"{r}/clock", beacons, obstacles]),
        # advanced subscriber: history query to the publishers' caches, their replies, late publishers
        rule("agents-history-query", ["query"], ("ingress", "egress"), [f"{obstacles}/@adv/**"]),
        rule("agents-history-reply", ["reply"], ("egress",), [obstacles]),
        rule("agents-history-live", ["declare_liveliness_subscriber"], ("ingress",), [f"{obstacles}/@adv/pub/**"]),
    ]
    per_agent: dict[int, list[str]] = {}
    for i in agent_ids:
        a, own = f"{r}/agent/{i}", f"{r}/cell/*/agent/{i}"
        per_agent[i] = [
            *agents_common,
            *publish(f"agent-{i}-pub", [f"{a}/cmd", f"{own}/beacon", f"{own}/obstacles", f"{r}/report/agent-{i}"],
                     [f"{r}/agent/*/cmd", beacons, obstacles, f"{r}/report/*"]),
            *subscribe(f"agent-{i}-own", [f"{a}/state"]),
            *membership(f"agent-{i}", f"{r}/alive/agent/{i}"),
            # its advanced publisher's cache: a queryable under its own key, replies with its own set only
            rule(f"agent-{i}-cache", ["declare_queryable"], ("ingress",), [f"{own}/obstacles/@adv/pub/**"]),
            rule(f"agent-{i}-cache-reply", ["reply"], ("ingress",), [f"{own}/obstacles"]),
        ]
        grant(f"agent-{i}", per_agent[i])
    for h in hosts:
        grant(host_name(h), list(dict.fromkeys(rid for i in h for rid in per_agent[i])))
    grant("simworld", [
        *publish("simworld-pub", [f"{r}/clock", f"{r}/truth", f"{r}/agent/*/state", f"{r}/report/simworld"],
                 [f"{r}/report/*"]),
        *subscribe("simworld-sub", [f"{r}/agent/*/cmd"]),
        *membership("simworld", f"{r}/alive/simworld"),
        # the truth's advanced publisher: its cache (a queryable, replies with the truth only) and heartbeats
        rule("simworld-truth-cache", ["declare_queryable"], ("ingress",), [f"{r}/truth/@adv/pub/**"]),
        rule("simworld-truth-reply", ["reply"], ("ingress",), [f"{r}/truth"]),
        *publish("simworld-truth-heartbeat", [f"{r}/truth/@adv/pub/**"]),
    ])
    grant("monitor", [
        *publish("monitor-pub", [f"{r}/event"]),
        *subscribe("monitor-sub", [f"{r}/truth", f"{r}/clock", f"{r}/report/*"]),
        *membership("monitor", f"{r}/alive/monitor"),
        # recovery of a lost truth: the world's heartbeats, queries to its cache and their replies
        *subscribe("monitor-truth-heartbeat", [f"{r}/truth/@adv/pub/**"]),
        rule("monitor-truth-query", ["query"], ("ingress", "egress"), [f"{r}/truth/@adv/**"]),
        rule("monitor-truth-reply", ["reply"], ("egress",), [f"{r}/truth"]),
    ])
    grant("observer", subscribe("observer-sub", [f"{r}/clock", f"{r}/event"]))
    # "intruder" has a certificate of the CA but no subject: the default (deny) applies to it.
    _dedupe(rules)
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects,
            "policies": policies}


def _dedupe(rules: list[dict[str, Any]]) -> None:
    seen: set[str] = set()
    keep = []
    for rl in rules:
        if rl["id"] not in seen:
            seen.add(rl["id"])
            keep.append(rl)
    rules[:] = keep


def _dump(cfg: dict[str, Any]) -> bytes:
    return (json.dumps(cfg, indent=2) + "\n").encode()


# --- files -------------------------------------------------------------------------------------------

def _private_dir(path: Path) -> None:
    path.mkdir(mode=0o700, parents=True, exist_ok=True)
    os.chmod(path, 0o700)


def _write(path: Path, data: bytes) -> None:
    """Write a file readable by its owner only (0600), whatever mode an earlier file had."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    try:
        os.fchmod(fd, 0o600)
        os.write(fd, data)
    finally:
        os.close(fd)


# --- certificates ------------------------------------------------------------------------------------

def _server_names(host: str) -> list[Any]:
    from cryptography import x509

    names: list[Any] = [x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1")),
                        x509.IPAddress(ipaddress.ip_address("::1"))]
    try:
        ip = ipaddress.ip_address(host)
        if str(ip) not in ("127.0.0.1", "::1"):
            names.append(x509.IPAddress(ip))
    except ValueError:
        if host != "localhost":
            names.append(x509.DNSName(host))
    return names


def _new_key() -> Any:
    from cryptography.hazmat.primitives.asymmetric import ec

    return ec.generate_private_key(ec.SECP256R1())


def _name(cn: str) -> Any:
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    return x509.Name([x509.NameAttribute(NameOID.ORGANIZATION_NAME, "reconswarm"),
                      x509.NameAttribute(NameOID.COMMON_NAME, cn)])


def _validity(builder: Any) -> Any:
    now = _dt.datetime.now(_dt.UTC)
    return builder.not_valid_before(now - _dt.timedelta(hours=1)).not_valid_after(now + _dt.timedelta(days=VALID_DAYS))


def _make_ca(run: str) -> tuple[Any, Any]:
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes

    key = _new_key()
    name = _name(f"reconswarm CA ({run})")
    ski = x509.SubjectKeyIdentifier.from_public_key(key.public_key())
    builder = (x509.CertificateBuilder().subject_name(name).issuer_name(name).public_key(key.public_key())
               .serial_number(x509.random_serial_number())
               .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
               .add_extension(x509.KeyUsage(digital_signature=False, content_commitment=False,
                                            key_encipherment=False, data_encipherment=False, key_agreement=False,
                                            key_cert_sign=True, crl_sign=True, encipher_only=False,
                                            decipher_only=False), critical=True)
               .add_extension(ski, critical=False))
    return key, _validity(builder).sign(key, hashes.SHA256())


def _issue(d: Path, cn: str, ca_key: Any, ca_cert: Any, server_names: list[Any] | None = None) -> None:
    """A leaf certificate (common name cn) and its key: d/<cn>-cert.pem, d/<cn>-key.pem."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.x509.oid import ExtendedKeyUsageOID

    key = _new_key()
    usage = [ExtendedKeyUsageOID.SERVER_AUTH] if server_names else [ExtendedKeyUsageOID.CLIENT_AUTH]
    builder = (x509.CertificateBuilder().subject_name(_name(cn)).issuer_name(ca_cert.subject)
               .public_key(key.public_key()).serial_number(x509.random_serial_number())
               .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
               .add_extension(x509.KeyUsage(digital_signature=True, content_commitment=False,
                                            key_encipherment=False, data_encipherment=False, key_agreement=False,
                                            key_cert_sign=False, crl_sign=False, encipher_only=False,
                                            decipher_only=False), critical=True)
               .add_extension(x509.ExtendedKeyUsage(usage), critical=False)
               .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
               .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()),
                              critical=False))
    if server_names:
        builder = builder.add_extension(x509.SubjectAlternativeName(server_names), critical=False)
    cert = _validity(builder).sign(ca_key, hashes.SHA256())
    _write(d / f"{cn}-key.pem", key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                                  serialization.NoEncryption()))
    _write(d / f"{cn}-cert.pem", _cert_pem(cert))


def _cert_pem(cert: Any) -> bytes:
    from cryptography.hazmat.primitives import serialization

    return bytes(cert.public_bytes(serialization.Encoding.PEM))
