"""The launcher, the command line and their checks. A process a launch started (RECONSWARM_DIE_WITH_PARENT set)
ends quietly on SIGINT until its node installs its own handler (reconswarm/net/runtime/lifecycle.Stopper): exit 130,
no KeyboardInterrupt traceback in its log, whenever the signal comes during its start."""

import os as _os
import signal as _signal


def _quiet_interrupt(_signum: int, _frame: object) -> None:
    raise SystemExit(130)


if _os.environ.get("RECONSWARM_DIE_WITH_PARENT"):
    _signal.signal(_signal.SIGINT, _quiet_interrupt)
