#!/usr/bin/env bash
# The test suite: sets itself up like run_local.sh, then runs pytest (arguments are passed on).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/setup_env.sh"
cd "$root"
exec "$venv/bin/python" -m pytest -q --durations=20 "$@"  # (the slowest 20: what CI time goes to)
