"""`python -m monitor`: the same as `reconswarm monitor`."""

import sys

from reconswarm_bringup.cli import app

if __name__ == "__main__":
    app(args=["monitor", *sys.argv[1:]], prog_name="python -m monitor")
