"""The wire's limits, in one place below everything that needs them: reconswarm.net.wire's decoders
enforce them, and the scenario loader (reconswarm/scenario/limits.py) refuses a scenario whose own messages
would exceed them. (Here rather than in reconswarm.net so that the scenario layer may import them.)"""

from __future__ import annotations

MAX_PAYLOAD_BYTES = 1 << 20  # 1 MiB: larger payloads are rejected before decoding
MAX_POINTS = 50_000  # contour points in a scan
MAX_OBSTACLES = 4_096  # obstacle ids in one obstacle set
MAX_VERTICES = 4_096  # vertices of one shared hull
MAX_IDS = 100_000  # agent ids in a clock's alive list (and a truth message)
MAX_STR = 128  # characters of a string (obstacle ids, stats keys, event kinds)
MAX_AGENT_ID = 2**31  # agent ids are 0..MAX_AGENT_ID (at most 10 digits in a key)
MAX_REASON = 256  # characters of a clock's end reason
MAX_STATS = 64  # entries of a clock's statistics
# What msgpack itself is allowed to unpack (any array, map, string in bytes).
MAX_ARRAY_LEN = MAX_POINTS * 3
MAX_MAP_LEN = MAX_OBSTACLES + 16
MAX_STR_BYTES = MAX_STR * 4
