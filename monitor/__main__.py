"""`python -m monitor`: the same commands as `reconswarm monitor` (monitor/cli.py)."""

import sys

from monitor.cli import monitor_app
from reconswarm.cli.console import run_app

if __name__ == "__main__":
    run_app(monitor_app, sys.argv[1:], "python -m monitor")
