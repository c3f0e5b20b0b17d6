"""Which agent host speaks for which agent, as the world learns it from the hosts' liveliness tokens (docs/wire.md).

A host's token `alive/host/<hid>/<members>` names its id and every agent it speaks for, in one key: it comes and
goes with the host's session, atomically, before its agents' own tokens (the host declares it first). The world
sends the states of an agent to its host (`host/<hid>/state`) and believes a command batch (`host/<hid>/cmd`) only
for the agents of that host.

Rules (a pure table, no zenoh):
- an agent's host is the first present claim on it, in the order the tokens came (a second host claiming an agent
  whose host is there is not believed while the first is: a forged token cannot take an agent's states away);
- a token that goes removes its claim; an agent whose every claim went keeps its last host (its states then go
  to a key nobody hears, as a dead agent's would: harmless; a host restarted under the same key, whose new token
  may come before the old one's end, keeps its agents).
"""

from __future__ import annotations


class Hosts:
    def __init__(self) -> None:
        self.claims: dict[int, tuple[int, ...]] = {}  # present host tokens: hid -> members, in the order they came
        self.owner: dict[int, int] = {}  # agent -> the host the world believes speaks for it

    def token(self, hid: int, members: tuple[int, ...], up: bool) -> None:
        """A host's token came (up) or went."""
        old = self.claims.get(hid, ())
        if up:
            self.claims[hid] = members  # (again: its newest list, in the place its first token took)
        else:
            self.claims.pop(hid, None)
        self._assign((*old, *members))

    def _assign(self, members: tuple[int, ...]) -> None:
        for aid in members:
            first = next((h for h, got in self.claims.items() if aid in got), None)
            if first is not None:
                self.owner[aid] = first

    def speaks_for(self, hid: int, aid: int) -> bool:
        """Host hid is the one the world believes for agent aid."""
        return self.owner.get(aid) == hid

    def group(self, ids: list[int]) -> dict[int, list[int]]:
        """The ids by their host (in their order); ids of no host yet are left out."""
        out: dict[int, list[int]] = {}
        for aid in ids:
            hid = self.owner.get(aid)
            if hid is not None:
                out.setdefault(hid, []).append(aid)
        return out
