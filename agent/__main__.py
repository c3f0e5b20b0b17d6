"""`python -m agent`: the same as `reconswarm agent`."""

import sys

from reconswarm_bringup.cli import app

if __name__ == "__main__":
    app(args=["agent", *sys.argv[1:]], prog_name="python -m agent")
