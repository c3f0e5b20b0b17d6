"""Secure mode: a CA, per-process credentials, mutual TLS and access control, for a deployment
(reconswarm_bringup/deployment.py): `run_local.sh --secure` (one host, or two with `--hosts 2`) and
`reconswarm credentials DEPLOYMENT.toml -o DIR` (real machines) both call `write()`.

`write()` puts into DIR (the launcher: OUTDIR/secrets/, every file of every host in it; the command: one
directory per host, DIR/<host>/, holding only what that host needs), directories 0700, every file 0600:

- `ca.pem`: the deployment's certificate authority (its private key is never written: nobody can issue more
  credentials for it once `write()` returns);
- `router-<host>-cert.pem`, `-key.pem` and `router-<host>.json5` for each host's router: it listens on its
  `tls/HOST:PORT` only (SAN: that host, 127.0.0.1, ::1, localhost), requires a certificate signed by the CA
  from everyone (mutual TLS), connects over mutual TLS to the routers of the hosts listed before it, and
  enforces its access rules (reconswarm_bringup/acl.py: deny by default, naming its own processes and the
  other hosts' routers);
- `<name>-cert.pem`, `<name>-key.pem`, `<name>.json5` for each process, connecting to its own host's router:
  `monitor`, `simworld`, `agent-<id>`, `agents-<ids>` for an agent host (one process, one session, e.g.
  `agents-1-5`), `observer` (a watcher of the clock and events: the launcher's) and, for the launcher only,
  `intruder` (a valid certificate the rules grant nothing: the flood fault uses it). A certificate's common
  name is its ACL subject; `<name>.json5` is the complete zenoh configuration (`zenoh.Config.from_file`).
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
from reconswarm.net.runtime.session import ZenohOptions
from reconswarm.net.timing import TIMING
from reconswarm.scenario.model import Scenario
from reconswarm.scenario.wire_limits import ids_runs_text
from reconswarm_bringup import acl, creddir
from reconswarm_bringup.deployment import Deployment, Host, tls_endpoint

ROLES = ("monitor", "simworld", "agent")
VALID_DAYS = 30
CONNECT_MS = 60_000  # how long a process tries to reach its router before it gives up
LOCAL_HOST = "A"  # the launcher's host (and B, with --hosts 2)
__all__ = ["Secrets", "create", "tls_endpoint", "write"]


@dataclass(frozen=True)
class Secrets:
    """What `write()` wrote: the deployment and where each participant's configuration is."""

    dir: Path
    deployment: Deployment
    split: bool = False  # one directory per host (DIR/<host>/) instead of every file in DIR

    @property
    def run(self) -> str:
        return self.deployment.run

    @property
    def agent_ids(self) -> tuple[int, ...]:
        return self.deployment.agent_ids

    @property
    def endpoint(self) -> str:
        """The first host's router endpoint (the world's, in a local run)."""
        return self.deployment.hosts[0].router

    @property
    def hosts(self) -> tuple[tuple[int, ...], ...]:
        """The agent hosts: processes of two agents or more."""
        return tuple(g for h in self.deployment.hosts for g in h.agent_processes if len(g) > 1)

    def host_dir(self, host: str) -> Path:
        return self.dir / host if self.split else self.dir

    @property
    def router_config(self) -> Path:
        return self.router_config_for(self.deployment.hosts[0].name)

    def router_config_for(self, host: str) -> Path:
        return self.host_dir(host) / f"router-{host}.json5"

    @property
    def ca(self) -> Path:
        return self.host_dir(self.deployment.hosts[0].name) / "ca.pem"

    def _dir_of(self, name: str) -> Path:
        dep = self.deployment
        for h in dep.hosts:
            if name in acl.processes(dep, h):
                return self.host_dir(h.name)
        return self.host_dir(dep.world_host)  # intruder: with the world

    def config_for(self, role: str, ident: str = "-") -> Path:
        """The client configuration of a role: `monitor`, `simworld` or `agent` (ident = the agent id, or an agent
        host's ids, e.g. `1-5`)."""
        if role == "agent" and ident in {ids_runs_text(h) for h in self.hosts}:
            return self._dir_of(f"agents-{ident}") / f"agents-{ident}.json5"
        if role == "agent":
            try:
                aid = int(ident)
            except ValueError:
                raise BadInput(f"secure: agent id {ident!r} is not an integer") from None
            if aid not in self.agent_ids:
                raise BadInput(f"secure: no credentials for agent {aid} (the scenario's agents: "
                               f"{', '.join(map(str, self.agent_ids))})")
            return self._dir_of(f"agent-{aid}") / f"agent-{aid}.json5"
        if role in ("monitor", "simworld", "observer", "intruder"):
            return self._dir_of(role) / f"{role}.json5"
        raise BadInput(f"secure: unknown role {role!r} (expected one of {', '.join(ROLES)})")

    def observer_options(self) -> ZenohOptions:
        """Zenoh options of the launcher's own watcher (may subscribe to the clock and events only)."""
        return ZenohOptions.build(None, None, "client", self.config_for("observer"))


def create(secrets_dir: Path, scenario: Scenario, endpoint: str, run: str | None = None,
           hosts: tuple[tuple[int, ...], ...] = (), *, ros2_domain: int | None = None,
           live_view: bool = False) -> Secrets:
    """The launcher's one-host secure run: every credential and configuration under secrets_dir.

    run: the run id of the key prefix `swarm/<run>` the access rules name (default: the scenario name);
    hosts: the agents of each agent process (default: one each)."""
    ep = tls_endpoint(endpoint)
    ids = tuple(a.id for a in scenario.agents)
    unknown = [a for h in hosts for a in h if a not in ids]
    if unknown:
        raise BadInput(f"secure: no agent {unknown[0]} in the scenario for an agent host")
    packed = {a for h in hosts for a in h}
    groups = (*hosts, *((a,) for a in ids if a not in packed))
    one = Host(LOCAL_HOST, ep, ids, tuple(sorted(groups, key=lambda g: ids.index(g[0]))))
    dep = Deployment(run or scenario.meta.name, (one,), LOCAL_HOST, LOCAL_HOST, ros2_domain, live_view)
    return write(secrets_dir, dep, intruder=True)


def write(out: Path, dep: Deployment, *, split: bool = False, install_dir: Path | None = None,
          intruder: bool = False) -> Secrets:
    """Create the CA and every credential and configuration of a deployment under out.

    split: one directory per host; install_dir: where each host's files will be on that host (the paths the
    configurations name; default: where they are written); intruder: also a certificate the rules grant nothing."""
    out = Path(out).resolve()
    sec = Secrets(out, dep, split)
    if split:  # the command's DIR: only what it made itself is touched (creddir.py)
        creddir.prepare(out, dep.run, {h.name: host_files(dep, h, intruder) for h in dep.hosts})
    else:  # the launcher's OUTDIR/secrets
        _private_dir(out)
        for old in out.iterdir():  # credentials of an earlier run (another CA, other agents)
            if old.is_file() and old.suffix in (".pem", ".json5"):
                old.unlink()
    ca_key, ca_cert = _make_ca(dep.run)
    for h in dep.hosts:
        d = sec.host_dir(h.name)
        ref = install_dir if install_dir is not None else d
        _write(d / "ca.pem", _cert_pem(ca_cert))
        _issue(d, h.router_name, ca_key, ca_cert, server_names=_server_names(_host_of(h.router)))
        _write(d / f"router-{h.name}.json5", _dump(router_config(dep, h, ref)))
        for name in _process_names(dep, h, intruder):
            _issue(d, name, ca_key, ca_cert)
            _write(d / f"{name}.json5", _dump(client_config(h, name, ref)))
    return sec


def _process_names(dep: Deployment, h: Host, intruder: bool) -> list[str]:
    return acl.processes(dep, h) + (["intruder"] if intruder and h.name == dep.world_host else [])


def host_files(dep: Deployment, h: Host, intruder: bool = False) -> list[str]:
    """The names of the files write() puts in a host's directory."""
    names = ["ca.pem"]
    for cn in (h.router_name, *_process_names(dep, h, intruder)):
        names += [f"{cn}-cert.pem", f"{cn}-key.pem"]
    return [*names, *(f"{n}.json5" for n in (h.router_name, *_process_names(dep, h, intruder)))]


# --- configurations ------------------------------------------------------------------------------------

def _host_of(endpoint: str) -> str:
    return endpoint.partition("/")[2].rpartition(":")[0].strip("[]")


def _base(mode: str, tls: dict[str, Any]) -> dict[str, Any]:
    """What every configuration of a secure run shares: no multicast, timestamps, the lease, mTLS with our CA."""
    return {
        "mode": mode,
        "scouting": {"multicast": {"enabled": False}},
        "timestamping": {"enabled": True},
        "transport": {"link": {"tx": {"lease": TIMING.lease_ms}, "tls": {**tls, "enable_mtls": True}}},
    }


def client_config(host: Host, name: str, ref: Path) -> dict[str, Any]:
    """A complete client configuration (to its host's router): `zenoh.Config.from_file` opens it as is."""
    conf = _base("client", {
        "root_ca_certificate": str(ref / "ca.pem"),
        "connect_private_key": str(ref / f"{name}-key.pem"),
        "connect_certificate": str(ref / f"{name}-cert.pem"),
        "verify_name_on_connect": True,
    })
    # (a router on another host, or in another namespace, may come up a minute after its clients on a busy machine)
    conf["connect"] = {"endpoints": [host.router], "timeout_ms": {"router": -1, "peer": -1, "client": CONNECT_MS}}
    return conf


def router_config(dep: Deployment, host: Host, ref: Path) -> dict[str, Any]:
    """A host's router: listens on its endpoint, connects to the routers of the hosts before it (mutual TLS with
    its own certificate both ways), and holds the access rules of its own processes."""
    me = host.router_name
    earlier = [h.router for h in dep.hosts[:dep.hosts.index(host)]]
    conf = _base("router", {
        "root_ca_certificate": str(ref / "ca.pem"),
        "listen_private_key": str(ref / f"{me}-key.pem"),
        "listen_certificate": str(ref / f"{me}-cert.pem"),
        "connect_private_key": str(ref / f"{me}-key.pem"),
        "connect_certificate": str(ref / f"{me}-cert.pem"),
        "verify_name_on_connect": True,
    })
    conf["listen"] = {"endpoints": [host.router]}
    if earlier:
        conf["connect"] = {"endpoints": earlier}
    conf["access_control"] = acl.router_acl(dep, host)
    return conf


def _dump(cfg: dict[str, Any]) -> bytes:
    return (json.dumps(cfg, indent=2) + "\n").encode()


# --- files -------------------------------------------------------------------------------------------

def _private_dir(path: Path) -> None:
    path.mkdir(mode=0o700, parents=True, exist_ok=True)
    os.chmod(path, 0o700)


def _write(path: Path, data: bytes) -> None:
    """Write a file readable by its owner only (0600), whatever mode an earlier file had; never through a
    symbolic link."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW, 0o600)
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
    # a router listens (server) and connects to the other hosts' routers (client)
    usage = ([ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH] if server_names
             else [ExtendedKeyUsageOID.CLIENT_AUTH])
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
