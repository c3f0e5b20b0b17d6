"""`python -m agent`: the same command as `reconswarm agent` (agent/cli.py)."""

import sys

from agent.cli import app
from reconswarm.cli.console import run_app

if __name__ == "__main__":
    run_app(app, sys.argv[1:], "python -m agent")
