"""`reconswarm credentials DEPLOYMENT.toml -o DIR`: the CA, every process's certificate and each host's router and
process zenoh configurations of a secure deployment on real machines (docs/security.md). The local launcher's
`--secure` makes its own the same way (reconswarm_bringup/secure.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from reconswarm.cli.console import fail
from reconswarm.errors import BadInput, ReconswarmError


def credentials_cmd(
    deployment_file: Annotated[Path, typer.Argument(metavar="DEPLOYMENT.toml",
                                                    help="Hosts, their routers and agents (docs/security.md).")],
    out: Annotated[Path, typer.Option(
        "-o", "--out", metavar="DIR",
        help="Where to write: one directory per host, DIR/<host>/ (0700, files 0600). DIR is new, empty, or a "
             "previous output of the same deployment holding nothing else.")],
    install_dir: Annotated[Path | None, typer.Option(
        "--install-dir", metavar="PATH",
        help="Where each host's directory will be on that host (the paths its configurations name; default: "
             "DIR/<host> as written).")] = None,
) -> None:
    """Make a secure deployment's credentials: a CA, each process's certificate and zenoh configuration, each
    host's router configuration (mutual TLS, access rules deny by default naming its own processes)."""
    from reconswarm_bringup import acl, deployment, secure

    try:
        dep = deployment.load(deployment_file)
        if install_dir is not None and not install_dir.is_absolute():
            raise BadInput(f"--install-dir {install_dir}: must be an absolute path")
        sec = secure.write(out, dep, split=True, install_dir=install_dir)
    except (ReconswarmError, OSError) as exc:
        fail(exc)
        return
    for h in dep.hosts:
        d = sec.host_dir(h.name)
        procs = acl.processes(dep, h)
        typer.echo(f"{d}/: router-{h.name}.json5 ({h.router}), {', '.join(f'{p}.json5' for p in procs)}")
    typer.echo(f"run every process with --run {dep.run} (the key prefix swarm/{dep.run} the access rules name)")


def register(app: typer.Typer) -> None:
    app.command("credentials")(credentials_cmd)
