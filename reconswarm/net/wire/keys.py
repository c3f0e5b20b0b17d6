"""Key expressions of one run (`swarm/<run>/...`) and their parser."""

from __future__ import annotations

from dataclasses import dataclass, field

from reconswarm.net.wire.cells import Cell, cell_chunk, chunk_cell
from reconswarm.scenario.wire_limits import agent_id_from_text, ids_from_text, ids_to_text

CELL_LEAVES = ("obstacles",)  # an agent's keys under a cell of its position (its beacons: in its host's batch)
HOST_BEACONS = "beacons"  # a host's batch of its agents' beacons in a cell (reconswarm/net/wire/batch.py)
HOST_LEAVES = ("state", "cmd")  # a host's batch of its agents' states (the world's), their commands (hostwire.py)


class WireError(ValueError):
    """A payload (or key) that must be dropped (and counted)."""


@dataclass(frozen=True)
class ParsedKey:
    """A key's kind ("agent", "host", "clock", "event", "truth", "alive", "report"), agent id (a host's key: its
    lowest agent id), leaf, the cell it was published under (`cell/<cx>_<cy>/agent/<id>/<leaf>`,
    `cell/<cx>_<cy>/host/<hid>/beacons`; None for every other key), and a host's token's members
    (`alive/host/<hid>/<members>`; None for every other key)."""

    kind: str
    agent_id: int | None
    leaf: str
    cell: Cell | None = None
    members: tuple[int, ...] | None = None


@dataclass(frozen=True)
class Keys:
    """All key expressions of one run (`swarm/<run>/...`)."""

    run: str
    _parsed: dict[str, ParsedKey] = field(default_factory=dict, compare=False, repr=False)

    @property
    def prefix(self) -> str:
        return f"swarm/{self.run}"

    def agent(self, agent_id: int, leaf: str) -> str:
        return f"{self.prefix}/agent/{agent_id}/{leaf}"

    def scan(self, agent_id: int) -> str:
        return self.agent(agent_id, "scan")

    def in_cell(self, cell: Cell, agent_id: int, leaf: str) -> str:
        """A key published under the spatial cell of the sender's position (reconswarm/net/wire/cells.py)."""
        return f"{self.prefix}/cell/{cell_chunk(cell)}/agent/{agent_id}/{leaf}"

    def host_beacons(self, cell: Cell | None, host: int | None) -> str:
        """A host's batch of its agents' beacons in a cell (None: every cell, every host)."""
        where = "*" if cell is None else cell_chunk(cell)
        return f"{self.prefix}/cell/{where}/host/{'*' if host is None else host}/{HOST_BEACONS}"

    def host(self, host: int | None, leaf: str) -> str:
        """A host's batch of its agents' states (`state`, the world's) or commands (`cmd`); None: every host."""
        return f"{self.prefix}/host/{'*' if host is None else host}/{leaf}"

    def alive_host(self, members: tuple[int, ...] | list[int]) -> str:
        """A host's liveliness token: its id (its lowest agent's) and every agent it speaks for, in one key."""
        return f"{self.prefix}/alive/host/{min(members)}/{ids_to_text(members)}"

    def obstacles(self, cell: Cell, agent_id: int) -> str:
        return self.in_cell(cell, agent_id, "obstacles")

    def cell_agents(self, cell: Cell | None, leaf: str) -> str:
        """Every agent's `leaf` (obstacles) in one cell, or in every cell (None)."""
        return f"{self.prefix}/cell/{'*' if cell is None else cell_chunk(cell)}/agent/*/{leaf}"

    def all_agents(self, leaf: str) -> str:
        return f"{self.prefix}/agent/*/{leaf}"

    @property
    def clock(self) -> str:
        return f"{self.prefix}/clock"

    @property
    def event(self) -> str:
        return f"{self.prefix}/event"

    @property
    def alive_all(self) -> str:
        return f"{self.prefix}/alive/**"

    def alive_agent(self, agent_id: int) -> str:
        return f"{self.prefix}/alive/agent/{agent_id}"

    @property
    def alive_simworld(self) -> str:
        return f"{self.prefix}/alive/simworld"

    @property
    def alive_monitor(self) -> str:
        return f"{self.prefix}/alive/monitor"

    @property
    def truth(self) -> str:
        return f"{self.prefix}/truth"

    def report(self, process: str) -> str:
        """A process's intrusion report (`simworld`, `agent-<id>`)."""
        return f"{self.prefix}/report/{process}"

    @property
    def report_all(self) -> str:
        return f"{self.prefix}/report/*"

    def parse(self, key: str) -> tuple[str, int | None, str]:
        """Classify a key: ("agent", id, leaf) (also for `cell/<cx>_<cy>/agent/<id>/<leaf>`) |
        ("host", its lowest agent id, "beacons") (`cell/<cx>_<cy>/host/<hid>/beacons`) |
        ("host", hid, "state" | "cmd") (`host/<hid>/<leaf>`) | ("alive", hid, "host") (`alive/host/<hid>/<members>`) |
        ("clock", None, "") | ("event", None, "") | ("truth", None, "") |
        ("alive", id or None, "agent" | "simworld" | "monitor") |
        ("report", agent id or None, "agent-<id>" | "simworld").
        Raises WireError for anything else. `parsed` also gives a cell key's cell."""
        p = self.parsed(key)
        return p.kind, p.agent_id, p.leaf

    def parsed(self, key: str) -> ParsedKey:
        """The key's parse (as `parse`, with its cell); raises WireError for a key of none of the run's shapes."""
        hit = self._parsed.get(key)
        if hit is not None:
            return hit
        out = self._parse(key)
        if len(self._parsed) < 100_000:
            self._parsed[key] = out
        return out

    def _parse(self, key: str) -> ParsedKey:
        pre = self.prefix + "/"
        if not key.startswith(pre):
            raise WireError(f"key {key!r} outside {self.prefix}")
        parts = key[len(pre):].split("/")
        if parts in (["clock"], ["event"], ["truth"]):
            return ParsedKey(parts[0], None, "")
        if len(parts) == 3 and parts[0] == "agent":
            return ParsedKey("agent", _key_id(parts[1], key), parts[2])
        if len(parts) == 5 and parts[0] == "cell" and parts[2] == "agent" and parts[4] in CELL_LEAVES:
            try:
                cell = chunk_cell(parts[1])
            except ValueError:
                raise WireError(f"bad cell in key {key!r}") from None
            return ParsedKey("agent", _key_id(parts[3], key), parts[4], cell)
        if len(parts) == 5 and parts[0] == "cell" and parts[2] == "host" and parts[4] == HOST_BEACONS:
            try:
                cell = chunk_cell(parts[1])
            except ValueError:
                raise WireError(f"bad cell in key {key!r}") from None
            return ParsedKey("host", _key_id(parts[3], key), parts[4], cell)
        if len(parts) == 3 and parts[0] == "host" and parts[2] in HOST_LEAVES:
            return ParsedKey("host", _key_id(parts[1], key), parts[2])
        if len(parts) == 4 and parts[:2] == ["alive", "host"]:
            hid, members = _key_id(parts[2], key), ids_from_text(parts[3])
            if members is None or members[0] != hid:
                raise WireError(f"bad members in host token {key!r} (canonical ids, the lowest the host's)")
            return ParsedKey("alive", hid, "host", members=members)
        if len(parts) == 3 and parts[:2] == ["alive", "agent"]:
            return ParsedKey("alive", _key_id(parts[2], key), "agent")
        if len(parts) == 2 and parts[0] == "report" and parts[1] == "simworld":
            return ParsedKey("report", None, parts[1])
        if len(parts) == 2 and parts[0] == "report" and parts[1].startswith("agent-"):
            return ParsedKey("report", _key_id(parts[1][6:], key), parts[1])
        if len(parts) == 2 and parts[0] == "alive" and parts[1] in ("simworld", "monitor"):
            return ParsedKey("alive", None, parts[1])
        raise WireError(f"unexpected key {key!r}")


def _key_id(text: str, key: str) -> int:
    """An agent id in a key: its canonical decimal alone (`03` or `٣` is another key than agent 3's, and no
    key of it)."""
    aid = agent_id_from_text(text)
    if aid is None:
        raise WireError(f"bad agent id in key {key!r}")
    return aid


