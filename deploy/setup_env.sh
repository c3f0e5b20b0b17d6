# Sourced by run_local.sh and run_tests.sh: make sure $venv holds the project and its dependencies.
# A fresh machine needs only Python >= 3.11 and the package registry.
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="${RECONSWARM_VENV:-$root/.venv}"
stamp="$venv/.reconswarm-installed"
want="$(sha256sum "$root/pyproject.toml" | cut -d' ' -f1)"
if [ ! -x "$venv/bin/python" ] || [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
    py=""
    for cand in python3.13 python3.12 python3.11 python3; do
        # (a pyenv shim for a version pyenv does not have says so on stderr: a probe's answer is its status)
        if command -v "$cand" >/dev/null 2>&1 && "$cand" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
            py="$cand"; break
        fi
    done
    if [ -z "$py" ]; then
        echo "reconswarm: error: Python >= 3.11 not found (install python3.11 or newer)" >&2
        exit 3
    fi
    echo "reconswarm: setting up $venv (first run: installing the project and its dependencies)..." >&2
    [ -x "$venv/bin/python" ] || "$py" -m venv "$venv"
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check --upgrade pip >&2
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check -e "$root[dev,dask,navground]" >&2
    echo "$want" > "$stamp"
fi
