#!/usr/bin/env bash
# The main job: the paper's mission (or yours) as separate processes over Zenoh on this machine.
#   deploy/run_local.sh [-n N] [-s SCENARIO] [-o OUTDIR] [--clock lockstep|realtime] [--speed X]
#                       [--planner P] [--router EP] [--secure] [--fault SPEC]... [--json] [--timeout S]
# Sets itself up on a fresh machine (a virtual environment in .venv with the project installed), then
# hands over to the launcher (reconswarm_bringup/launcher.py). Ctrl-C or SIGTERM stops every process it started.
# Paths (-s, -o, RECONSWARM_PROFILE) are relative to the directory it is run from; without -o each run writes
# its own runs/YYYYMMDD-HHMMSS/ in the project, and runs/latest links to the newest.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/setup_env.sh"
# This checkout's code, whatever the directory (-P: not the caller's directory on the module path).
export PYTHONPATH="$root${PYTHONPATH:+:$PYTHONPATH}"
exec "$venv/bin/python" -P -m reconswarm_bringup.cli_launch "$@"
