"""`python -m simworld`: the same command as `reconswarm simworld` (simworld/cli.py)."""

import sys

from reconswarm.cli.console import run_app
from simworld.cli import app

if __name__ == "__main__":
    run_app(app, sys.argv[1:], "python -m simworld")
