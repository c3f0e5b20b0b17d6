"""`python -m simworld`: the same as `reconswarm simworld`."""

import sys

from reconswarm_bringup.cli import app

if __name__ == "__main__":
    app(args=["simworld", *sys.argv[1:]], prog_name="python -m simworld")
