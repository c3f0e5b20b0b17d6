"""Scenario files (TOML): frozen dataclasses, strict validation, and the TOML writer.

Every refusal is a `BadInput` whose message is one line: `FILE: field.path: what is wrong`.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np

from reconswarm.errors import BadInput
from reconswarm.geometry.pairs import pairs_within
from reconswarm.geometry.plane import (
    distance_to_polygon,
    is_strictly_convex,
    norm2,
    polygon_area,
)
from reconswarm.scenario import limits
from reconswarm.scenario.toml_reader import TableReader
from reconswarm.scenario.wire_limits import MAX_AGENT_ID


class PlannerKind(StrEnum):
    """Which planner the agents run: the paper's reconfigurable APF, the virtual-leader benchmark, or one of
    navground's behaviours (reconswarm.planners.registry maps each name to its module)."""

    RECONFIGURABLE = "reconfigurable"
    VIRTUAL_LEADER = "virtual-leader"
    ORCA = "orca"
    HRVO = "hrvo"
    HL = "hl"
    SOCIAL_FORCE = "social-force"


PLANNERS = tuple(k.value for k in PlannerKind)


@dataclass(frozen=True)
class ScenarioMeta:
    name: str
    seed: int
    duration_s: float
    dt_s: float


@dataclass(frozen=True)
class PlannerConfig:
    kind: PlannerKind
    k_att: float
    target_radius_m: float
    psi_mps: float
    d_safe_m: float
    d_max_m: float
    sensing_range_m: float
    link_range_m: float
    perturbation_mps: float = 0.0
    converge_tol_m: float = 0.5
    stall_window_s: float = 5.0


@dataclass(frozen=True)
class WorldConfig:
    max_speed_mps: float = 0.0
    max_turn_rate_radps: float = 0.0


@dataclass(frozen=True)
class AgentSpec:
    id: int
    start_m: tuple[float, float]
    radius_m: float
    offset_m: tuple[float, float]
    heading_rad: float = 0.0
    head_offset_m: float = 0.5


@dataclass(frozen=True)
class ObstacleSpec:
    id: str
    vertices_m: tuple[tuple[float, float], ...]  # counter-clockwise (normalised on load)


@dataclass(frozen=True)
class Scenario:
    meta: ScenarioMeta
    planner: PlannerConfig
    world: WorldConfig
    target_m: tuple[float, float]
    agents: tuple[AgentSpec, ...]  # sorted by id
    obstacles: tuple[ObstacleSpec, ...]  # sorted by id
    source: str = field(default="<memory>", compare=False)

    # Arrays in agent-id order, built on demand (the dataclass stays hashable and immutable).
    def _column(self, attr: str, dtype: type = np.float64) -> np.ndarray:
        return np.array([getattr(a, attr) for a in self.agents], dtype=dtype)

    @property
    def ids(self) -> np.ndarray:  # (N,)
        return self._column("id", np.int64)

    @property
    def starts(self) -> np.ndarray:  # (N, 2)
        return self._column("start_m").reshape(-1, 2)

    @property
    def radii(self) -> np.ndarray:  # (N,)
        return self._column("radius_m")

    @property
    def offsets(self) -> np.ndarray:  # (N, 2)
        return self._column("offset_m").reshape(-1, 2)

    @property
    def headings(self) -> np.ndarray:  # (N,)
        return self._column("heading_rad")

    @property
    def head_offsets(self) -> np.ndarray:  # (N,)
        return self._column("head_offset_m")

    def polygon(self, k: int) -> np.ndarray:  # (V, 2)
        return np.array(self.obstacles[k].vertices_m, dtype=np.float64)

    def agent_index(self, agent_id: int) -> int:
        for k, a in enumerate(self.agents):
            if a.id == agent_id:
                return k
        raise KeyError(agent_id)

    def with_planner(self, kind: str | PlannerKind) -> Scenario:
        from dataclasses import replace

        if kind not in PLANNERS:
            raise BadInput(f"--planner: unknown planner {kind!r} (expected one of {', '.join(PLANNERS)})")
        return replace(self, planner=replace(self.planner, kind=PlannerKind(kind)))

    def with_seed(self, seed: int) -> Scenario:
        from dataclasses import replace

        return replace(self, meta=replace(self.meta, seed=seed))


# ---------------------------------------------------------------------------------------------- loading


def load(path: str | Path, wire: bool = True) -> Scenario:
    """Read and validate a scenario file; raise BadInput naming the file and field on any problem.

    wire: also refuse what the wire cannot carry (False only where no wire is used: the in-process engine)."""
    p = Path(path)
    src = str(path)
    try:
        text = p.read_text()
    except FileNotFoundError:
        raise BadInput(f"{src}: file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise BadInput(f"{src}: cannot read: {exc}") from None
    return parse(text, src, wire)


def parse(text: str, source: str = "<scenario>", wire: bool = True) -> Scenario:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise BadInput(f"{source}: not valid TOML: {exc}") from None
    scenario, _ = _build(data, source, wire)
    return scenario


def check(path: str | Path, wire: bool = True) -> tuple[Scenario, list[str]]:
    """Validate a file, returning the scenario and its warnings (e.g. Assumption 4.1 violations)."""
    scen = load(path, wire)
    return scen, warnings(scen)


def _build(data: dict[str, Any], src: str, wire: bool = True) -> tuple[Scenario, None]:
    r = TableReader(src)
    r.keys(data, "", {"scenario", "planner", "target", "agents"}, {"world", "obstacles"})

    s = r.table(data["scenario"], "scenario")
    r.keys(s, "scenario", {"name", "duration_s", "dt_s"}, {"seed"})
    meta = ScenarioMeta(
        name=r.string(s, "scenario", "name"),
        seed=r.integer(s, "scenario", "seed", 0, lo=0),
        duration_s=r.number(s, "scenario", "duration_s", check=lambda v: v > 0, need="> 0"),
        dt_s=r.number(s, "scenario", "dt_s", check=lambda v: 0 < v <= 1.0, need="in (0, 1]"),
    )
    if not all((c.isascii() and c.isalnum()) or c in "-_." for c in meta.name):
        raise r.fail("scenario.name", f"only ASCII letters, digits, '-', '_' and '.' (it names zenoh keys), "
                                      f"got {meta.name!r}")
    if meta.duration_s / meta.dt_s > 10_000_000:
        raise r.fail("scenario.duration_s", "more than 10 million steps of dt_s")

    pl = r.table(data["planner"], "planner")
    req = {"k_att", "target_radius_m", "psi_mps", "d_safe_m", "d_max_m", "sensing_range_m", "link_range_m"}
    r.keys(pl, "planner", req, {"kind", "perturbation_mps", "converge_tol_m", "stall_window_s"})
    kind = r.string(pl, "planner", "kind", "reconfigurable")
    if kind not in PLANNERS:
        raise r.fail("planner.kind", f"expected one of {', '.join(PLANNERS)}, got {kind!r}")
    pos = {"check": lambda v: v > 0, "need": "> 0"}
    planner = PlannerConfig(
        kind=PlannerKind(kind),
        k_att=r.number(pl, "planner", "k_att", **pos),  # type: ignore[arg-type]
        target_radius_m=r.number(pl, "planner", "target_radius_m", **pos),  # type: ignore[arg-type]
        psi_mps=r.number(pl, "planner", "psi_mps", check=lambda v: v < 0, need="negative (Ψ < 0, as in the paper)"),
        d_safe_m=r.number(pl, "planner", "d_safe_m", check=lambda v: v >= 0, need=">= 0"),
        d_max_m=r.number(pl, "planner", "d_max_m", **pos),  # type: ignore[arg-type]
        sensing_range_m=r.number(pl, "planner", "sensing_range_m", **pos),  # type: ignore[arg-type]
        link_range_m=r.number(pl, "planner", "link_range_m", **pos),  # type: ignore[arg-type]
        perturbation_mps=r.number(pl, "planner", "perturbation_mps", 0.0, check=lambda v: v >= 0, need=">= 0"),
        converge_tol_m=r.number(pl, "planner", "converge_tol_m", 0.5, **pos),  # type: ignore[arg-type]
        stall_window_s=r.number(pl, "planner", "stall_window_s", 5.0, **pos),  # type: ignore[arg-type]
    )
    if planner.d_max_m <= planner.d_safe_m:
        raise r.fail("planner.d_max_m", f"must exceed d_safe_m ({planner.d_safe_m}), got {planner.d_max_m}")
    if planner.stall_window_s < 2 * meta.dt_s:
        raise r.fail("planner.stall_window_s", f"must be at least two steps of dt_s, got {planner.stall_window_s}")

    world = WorldConfig()
    if "world" in data:
        w = r.table(data["world"], "world")
        r.keys(w, "world", set(), {"max_speed_mps", "max_turn_rate_radps"})
        world = WorldConfig(
            max_speed_mps=r.number(w, "world", "max_speed_mps", 0.0, check=lambda v: v >= 0, need=">= 0 (0: no limit)"),
            max_turn_rate_radps=r.number(w, "world", "max_turn_rate_radps", 0.0, check=lambda v: v >= 0,
                                         need=">= 0 (0: no limit)"),
        )

    t = r.table(data["target"], "target")
    r.keys(t, "target", {"center_m"}, set())
    target = r.point_key(t, "target", "center_m")

    agents = _agents(r, data["agents"])
    obstacles = _obstacles(r, data.get("obstacles", []))
    scen = Scenario(meta, planner, world, target, agents, obstacles, source=src)
    # Magnitudes, stability, memory and, where a wire is used, what it can carry (reconswarm/scenario/limits.py),
    # first problem found.
    agent_path = {int(a["id"]): f"agents[{k}]" for k, a in enumerate(data["agents"])}
    obstacle_path = {str(o["id"]): f"obstacles[{k}]" for k, o in enumerate(data.get("obstacles", []))}
    for path, msg in limits.problems(scen, agent_path, obstacle_path):
        raise r.fail(path, msg)
    for path, msg in limits.wire_problems(scen, obstacle_path) if wire else ():
        raise r.fail(path, f"{msg} (a limit of the distributed run: `reconswarm sim` has no wire)")
    _check_placement(r, scen, data)
    return scen, None


def _agents(r: TableReader, raw: Any) -> tuple[AgentSpec, ...]:
    if not isinstance(raw, list) or not raw:
        raise r.fail("agents", "expected at least one [[agents]] table")
    seen: dict[int, int] = {}
    out = []
    for k, a in enumerate(raw):
        path = f"agents[{k}]"
        a = r.table(a, path)
        r.keys(a, path, {"id", "start_m", "radius_m", "offset_m"}, {"heading_rad", "head_offset_m"})
        aid = r.integer(a, path, "id")
        if aid < 0 or aid > MAX_AGENT_ID:
            raise r.fail(f"{path}.id", f"must be in [0, {MAX_AGENT_ID}] (the wire's agent ids), got {aid}")
        if aid in seen:
            raise r.fail(f"{path}.id", f"duplicate agent id {aid} (also agents[{seen[aid]}])")
        seen[aid] = k
        out.append(AgentSpec(
            id=aid,
            start_m=r.point_key(a, path, "start_m"),
            radius_m=r.number(a, path, "radius_m", check=lambda v: v > 0, need="> 0"),
            offset_m=r.point_key(a, path, "offset_m"),
            heading_rad=r.number(a, path, "heading_rad", 0.0),
            head_offset_m=r.number(a, path, "head_offset_m", 0.5, check=lambda v: v > 0, need="> 0"),
        ))
    return tuple(sorted(out, key=lambda a: a.id))


def _obstacles(r: TableReader, raw: Any) -> tuple[ObstacleSpec, ...]:
    if not isinstance(raw, list):
        raise r.fail("obstacles", "expected an array of [[obstacles]] tables")
    seen: dict[str, int] = {}
    out = []
    for k, o in enumerate(raw):
        path = f"obstacles[{k}]"
        o = r.table(o, path)
        r.keys(o, path, {"id", "vertices_m"}, set())
        oid = r.string(o, path, "id")
        if not all((c.isascii() and c.isalnum()) or c in "-_." for c in oid):
            raise r.fail(f"{path}.id", f"only letters, digits, '-', '_' and '.', got {oid!r}")
        if oid in seen:
            raise r.fail(f"{path}.id", f"duplicate obstacle id {oid!r} (also obstacles[{seen[oid]}])")
        seen[oid] = k
        vraw = o["vertices_m"]
        where = f"{path}.vertices_m"
        if not isinstance(vraw, list) or len(vraw) < 3:
            raise r.fail(where, "expected at least 3 vertices [[x, y], ...]")
        verts = np.array([r.point(v, f"{where}[{j}]") for j, v in enumerate(vraw)])
        for j in range(len(verts)):
            if float(norm2(verts[j] - verts[j - 1])) < 1e-6:
                raise r.fail(f"{where}[{j}]", "repeats the previous vertex (degenerate polygon)")
        area = polygon_area(verts)
        scale = float(np.max(norm2(verts - verts.mean(axis=0))))
        if abs(area) < 1e-6 * max(scale, 1.0) ** 2:
            raise r.fail(where, "degenerate polygon (zero area)")
        if not is_strictly_convex(verts):
            raise r.fail(where, "polygon is not strictly convex (obstacles must be convex, Assumption 2.1)")
        if area < 0:
            verts = verts[::-1]
        out.append(ObstacleSpec(id=oid, vertices_m=tuple((float(x), float(y)) for x, y in verts)))
    return tuple(sorted(out, key=lambda o: o.id))


def _check_placement(r: TableReader, s: Scenario, data: dict[str, Any]) -> None:
    # The error names agents by their position in the file.
    file_index = {int(a["id"]): k for k, a in enumerate(data["agents"])}
    starts, radii = s.starts, s.radii
    if len(s.agents) > 1:
        pairs = pairs_within(starts, 2 * float(radii.max()))
        if pairs.shape[0]:
            gap = norm2(starts[pairs[:, 0]] - starts[pairs[:, 1]]) - radii[pairs[:, 0]] - radii[pairs[:, 1]]
            bad = np.flatnonzero(gap < 0)
            if bad.size:
                i, j = pairs[bad[0]]
                a, b = s.agents[i], s.agents[j]
                raise r.fail(f"agents[{file_index[b.id]}].start_m",
                             f"agent {b.id} overlaps agent {a.id} (gap {gap[bad[0]]:.3f} m)")
    for k in range(len(s.obstacles)):
        d, _ = distance_to_polygon(starts, s.polygon(k))
        bad = np.flatnonzero(d < radii)
        if bad.size:
            a = s.agents[int(bad[0])]
            raise r.fail(f"agents[{file_index[a.id]}].start_m",
                         f"agent {a.id} starts inside or touching obstacle {s.obstacles[k].id!r}")


def warnings(s: Scenario) -> list[str]:
    """Conditions the paper's theory needs but a run can live without (Assumptions 4.1 and 4.2), and
    those a collision-free run needs (limits.physics_warnings)."""
    out = [f"{s.source}: {path}: {msg}" for path, msg in limits.physics_warnings(s)]
    offs, radii = s.offsets, s.radii
    reach = 2 * float(radii.max()) + s.planner.d_max_m
    for i, j in pairs_within(offs, reach):
        need = radii[i] + radii[j] + s.planner.d_max_m
        got = float(norm2(offs[i] - offs[j]))
        if got < need:
            out.append(f"{s.source}: agents: offsets of agents {s.agents[i].id} and {s.agents[j].id} are "
                       f"{got:.2f} m apart, below d_max,ij = {need:.2f} m (Assumption 4.1)")
            if len(out) >= 5:
                out.append(f"{s.source}: agents: (further Assumption 4.1 warnings omitted)")
                break
    slots = np.asarray(s.target_m) + offs
    for k in range(len(s.obstacles)):
        d, _ = distance_to_polygon(slots, s.polygon(k))
        bad = np.flatnonzero(d < radii + s.planner.d_max_m)
        if bad.size:
            out.append(f"{s.source}: obstacles[{k}]: obstacle {s.obstacles[k].id!r} lies within d_max of the slot "
                       f"of agent {s.agents[int(bad[0])].id} (Assumption 4.2)")
    return out


# ---------------------------------------------------------------------------------------------- writing


def _f(v: float) -> str:
    return repr(float(v))


def to_toml(s: Scenario) -> str:
    """Serialise a scenario; `parse(to_toml(s))` equals `s`."""
    p = s.planner
    lines = [
        "[scenario]",
        f'name = "{s.meta.name}"',
        f"seed = {s.meta.seed}",
        f"duration_s = {_f(s.meta.duration_s)}",
        f"dt_s = {_f(s.meta.dt_s)}",
        "",
        "[planner]",
        f'kind = "{p.kind.value}"',
    ]
    for key in ("k_att", "target_radius_m", "psi_mps", "d_safe_m", "d_max_m", "sensing_range_m", "link_range_m",
                "perturbation_mps", "converge_tol_m", "stall_window_s"):
        lines.append(f"{key} = {_f(getattr(p, key))}")
    lines += ["", "[world]", f"max_speed_mps = {_f(s.world.max_speed_mps)}",
              f"max_turn_rate_radps = {_f(s.world.max_turn_rate_radps)}", "",
              "[target]", f"center_m = [{_f(s.target_m[0])}, {_f(s.target_m[1])}]"]
    for a in s.agents:
        lines += ["", "[[agents]]", f"id = {a.id}", f"start_m = [{_f(a.start_m[0])}, {_f(a.start_m[1])}]",
                  f"heading_rad = {_f(a.heading_rad)}", f"radius_m = {_f(a.radius_m)}",
                  f"offset_m = [{_f(a.offset_m[0])}, {_f(a.offset_m[1])}]", f"head_offset_m = {_f(a.head_offset_m)}"]
    for o in s.obstacles:
        verts = ", ".join(f"[{_f(x)}, {_f(y)}]" for x, y in o.vertices_m)
        lines += ["", "[[obstacles]]", f'id = "{o.id}"', f"vertices_m = [{verts}]"]
    return "\n".join(lines) + "\n"
