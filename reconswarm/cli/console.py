"""Console conventions shared by every command: one-line errors, JSON output, the mission's exit code, and
`run_app`, how a command line is run (`reconswarm`, `python -m agent|simworld|monitor`)."""

from __future__ import annotations

import json
import sys
from typing import Any

import typer

from reconswarm.errors import BadInput, ReconswarmError

_debug = False


def set_debug(on: bool) -> None:
    """`--debug`: errors raise (traceback) instead of printing one line."""
    global _debug
    _debug = on


def is_debug() -> bool:
    return _debug


def fail(exc: BaseException, prog: str = "reconswarm") -> None:
    """Print one line and exit with the error's code."""
    if _debug:
        raise exc
    code = exc.exit_code if isinstance(exc, ReconswarmError) else 1
    typer.echo(f"{prog}: error: {exc}", err=True)
    raise typer.Exit(code)


def print_json(obj: Any) -> None:
    sys.stdout.write(json.dumps(obj, indent=2) + "\n")


def plural(n: int, word: str) -> str:
    """`1 agent`, `2 agents`, `0 obstacles`."""
    return f"{n} {word}" + ("" if n == 1 else "s")


def mission_exit_code(summary: dict[str, Any]) -> int:
    return 0 if summary.get("converged") and not summary.get("collisions") else 1


def unconverged_reason(summary: dict[str, Any], warns: list[str]) -> list[str]:
    """Lines for the end of a run that ran its whole duration without converging while its scenario carried
    warnings (`reconswarm scenario check`'s: slots closer than d_max,ij, an obstacle within d_max of a slot, ...):
    those are the likely reason. None for a converged run, one stopped early, or a scenario without warnings."""
    if summary.get("converged") or not summary.get("finished") or not warns:
        return []
    head = (f"not converged in {summary.get('duration_s')} s; the likely reason is the scenario's "
            f"warning{'s' if len(warns) > 1 else ''} (reconswarm scenario check):")
    return [head, *(f"  {w}" for w in warns)]


def run_app(app: typer.Typer, args: list[str], prog_name: str | None = None) -> None:
    """Run a typer application on `args` and exit. An OSError about a path no command checked for is still one
    line naming it, exit 2 (`--debug`: the traceback)."""
    try:
        app(args=args, prog_name=prog_name)
    except OSError as exc:
        if is_debug() or exc.filename is None:
            raise
        sys.stderr.write(f"reconswarm: error: {exc.filename}: {exc.strerror or exc}\n")
        sys.exit(BadInput.exit_code)
