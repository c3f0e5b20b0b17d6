"""The wire's limits, in one place below everything that needs them: reconswarm.net.wire.wire's decoders
enforce them, and the scenario loader (reconswarm/scenario/limits.py) refuses a scenario whose own messages
would exceed them. (Here rather than in reconswarm.net so that the scenario layer may import them.)

Also the one reader of an agent id (or a cell coordinate) written as text, in a key expression
(`agent/<id>/...`, `alive/agent/<id>`, `report/agent-<id>`, `cell/<cx>_<cy>/...`), a ROS 2 topic
(`/robot_<id>/...`) or on the command line (`--ids`): `int_from_text`. Only the canonical decimal of a number
in range is read: ASCII digits, no sign but a minus on a negative, no leading zero (but "0" itself). Anything
else is no id: `²` (`str.isdigit`, but `int()` refuses it), `٣` (`int()` reads it as 3), `03` and `+3` (another
key than agent 3's, which would speak for it), `-0`, and more digits than the range has.
"""

from __future__ import annotations

import re
from collections.abc import Sequence

MAX_PAYLOAD_BYTES = 1 << 20  # 1 MiB: larger payloads are rejected before decoding
MAX_POINTS = 50_000  # contour points in a scan
MAX_OBSTACLES = 4_096  # obstacle ids in one obstacle set
MAX_VERTICES = 4_096  # vertices of one shared hull
MAX_IDS = 100_000  # agent ids in a clock's alive list (and a truth message)
MAX_STR = 128  # characters of a string (obstacle ids, stats keys, event kinds)
MAX_AGENT_ID = 2**31 - 1  # agent ids are 0..MAX_AGENT_ID (a signed 32-bit integer; at most 10 digits in a key)
MAX_REASON = 256  # characters of a clock's end reason
MAX_STATS = 64  # entries of a clock's statistics
# What msgpack itself is allowed to unpack (any array, map, string in bytes).
MAX_ARRAY_LEN = MAX_POINTS * 3
MAX_MAP_LEN = MAX_OBSTACLES + 16
MAX_STR_BYTES = MAX_STR * 4

_CANONICAL = re.compile(r"-?(?:0|[1-9][0-9]*)")  # ([0-9]: ASCII only, where \d would take any Unicode digit)


def int_from_text(text: str, lo: int, hi: int) -> int | None:
    """The integer whose canonical decimal `text` is, if it lies in lo..hi; None for any other text (never
    raises: a key from the wire is any string)."""
    if len(text) > max(len(str(lo)), len(str(hi))) or _CANONICAL.fullmatch(text) is None or text == "-0":
        return None
    v = int(text)
    return v if lo <= v <= hi else None


def agent_id_from_text(text: str) -> int | None:
    """An agent id (0..MAX_AGENT_ID) written canonically (see `int_from_text`); None for anything else."""
    return int_from_text(text, 0, MAX_AGENT_ID)


def ids_to_text(ids: tuple[int, ...] | list[int]) -> str:
    """A set of agent ids in its one canonical text, `1-5,9`: ascending runs of consecutive ids as ranges (what a
    host's liveliness token names, `alive/host/<hid>/<members>`)."""
    return ids_runs_text(sorted(set(ids)))


def ids_runs_text(ids: Sequence[int]) -> str:
    """The ids in the order given, runs of consecutive ids as ranges: `1-3,5,9,7-8` (what `--ids` takes)."""
    parts: list[str] = []
    start = prev = ids[0]
    for a in [*ids[1:], None]:
        if a is not None and a == prev + 1:
            prev = a
            continue
        parts.append(str(start) if start == prev else f"{start}-{prev}")
        if a is not None:
            start = prev = a
    return ",".join(parts)


def ids_from_text(text: str, most: int = MAX_IDS) -> tuple[int, ...] | None:
    """The ids whose canonical text (`ids_to_text`) `text` is, ascending; None for any other text (a range of one
    id, ranges out of order, touching or overlapping, more than `most` ids, a non-canonical number)."""
    out: list[int] = []
    if not text or len(text) > 16 * most:
        return None
    for part in text.split(","):
        lo, dash, hi = part.partition("-")
        a = agent_id_from_text(lo)
        b = agent_id_from_text(hi) if dash else a
        if a is None or b is None or (dash and b <= a) or (out and a <= out[-1] + 1):
            return None
        if len(out) + b - a + 1 > most:
            return None
        out.extend(range(a, b + 1))
    return tuple(out)
