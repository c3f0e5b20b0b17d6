#!/usr/bin/env bash
# The main job: the paper's mission (or yours) as separate processes over Zenoh on this machine.
#   deploy/run_local.sh [-n N] [-s SCENARIO] [-o OUTDIR] [--clock lockstep|realtime] [--speed X]
#                       [--planner P] [--router EP] [--secure] [--fault SPEC]... [--json] [--timeout S]
# Sets itself up on a fresh machine (a virtual environment in .venv with the project installed), then
# hands over to the launcher (reconswarm_bringup/launcher.py). Ctrl-C or SIGTERM stops every process it started.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/setup_env.sh"
cd "$root"
exec "$venv/bin/python" -m reconswarm_bringup.cli_launch "$@"
