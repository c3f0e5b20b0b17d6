#!/usr/bin/env bash
# The main job: the paper's mission (or yours) as separate processes over Zenoh on this machine.
#   deploy/run_local.sh [-n N] [-s SCENARIO] [-o OUTDIR] [--clock lockstep|realtime] [--speed X]
#                       [--planner P] [--router EP] [--secure] [--fault SPEC]...
# Sets itself up on a fresh machine (a virtual environment in .venv with the project installed), then
# hands over to the launcher (reconswarm/launcher.py). Ctrl-C or SIGTERM stops every process it started.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="${RECONSWARM_VENV:-$root/.venv}"
stamp="$venv/.reconswarm-installed"
want="$(sha256sum "$root/pyproject.toml" | cut -d' ' -f1)"

if [ ! -x "$venv/bin/python" ] || [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
    py=""
    for cand in python3.13 python3.12 python3.11 python3; do
        if command -v "$cand" >/dev/null 2>&1 && "$cand" -c 'import sys; sys.exit(sys.version_info < (3, 11))'; then
            py="$cand"; break
        fi
    done
    if [ -z "$py" ]; then
        echo "run_local: error: Python >= 3.11 not found (install python3.11 or newer)" >&2
        exit 3
    fi
    echo "run_local: setting up $venv (first run; this installs the dependencies)..." >&2
    [ -x "$venv/bin/python" ] || "$py" -m venv "$venv"
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check --upgrade pip >&2
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check -e "$root[dev]" >&2
    echo "$want" > "$stamp"
fi
cd "$root"
exec "$venv/bin/python" -m reconswarm.launcher "$@"
