"""The access rules of a secure deployment's routers (zenoh `access_control`, deny by default).

zenoh's ACL sees only a router's direct neighbours, so each host's router holds the rules of its own processes
(each a subject by its certificate's common name) and, for each other host's router (one subject), what
crosses between the hosts: what the other hosts' processes may send and receive (their router holds their
own rules), and what ours may send their way; nothing else (our clock, say, never comes in from there).
The rules (`R` = `swarm/<run>`) allow, per process and nothing else:

- agent i, hosted in a process whose lowest agent id is h (h = i for a lone agent) with agents M (`1-5,9`):
  put its host's command batches `R/host/h/cmd`, `R/cell/*/agent/i/obstacles` (in any cell, under its own id
  only), its host's beacon batches `R/cell/*/host/h/beacons` (under its host's id only), its intrusion report
  `R/report/agent-i`; tokens `R/alive/agent/i` and its host's `R/alive/host/h/M` (that key alone); the advanced
  publisher's cache (queryable `R/cell/*/agent/i/obstacles/@adv/pub/**`, replies on
  `R/cell/*/agent/i/obstacles`); subscribe (and receive) its host's state batches `R/host/h/state`, `R/clock`,
  `R/cell/*/host/*/beacons`, `R/cell/*/agent/*/obstacles`;
  history queries on `R/cell/*/agent/*/obstacles/@adv/**`; liveliness subscriptions on `R/alive/**` and
  `R/cell/*/agent/*/obstacles/@adv/pub/**`. An agent host (`agents-1-5`): what each of its agents may.
- simworld: put `R/clock`, `R/truth`, `R/host/*/state`, `R/report/simworld`; token `R/alive/simworld`;
  subscribe `R/host/*/cmd`, liveliness `R/alive/**`; the truth's advanced publisher.
- monitor: put `R/event`; token `R/alive/monitor`; subscribe `R/truth`, `R/clock`, `R/report/*`, liveliness
  `R/alive/**`; recovery of a lost truth. With the live view (`--foxglove`): the obstacle sets it draws
  (subscribe, history queries and their replies, the publishers' liveliness), as an agent reads them.
- observer (the launcher's watcher): subscribe `R/clock`, `R/event`.
- With ROS 2 (domain D, rmw_zenoh's keys): agent i puts `D/robot_i/cmd_vel/**` and subscribes
  `D/robot_i/odom/**` and its scan `R/agent/i/scan` (which simworld puts on `R/agent/*/scan`);
  simworld puts `D/robot_$*/odom/**` and subscribes `D/robot_$*/cmd_vel/**`; each declares
  its node's liveliness tokens only (`@ros2_lv/D/*/*/*/*/*/*/<node>` and below: `agent_i`, `simworld`).
- Any other certificate of the CA (`intruder`): nothing.

Ingress rules say what a subject may send to the router, egress rules what the router may forward to it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from reconswarm.net.wire.keys import Keys
from reconswarm.scenario.wire_limits import ids_runs_text
from reconswarm_bringup.deployment import Deployment, Host

FLOWS = ("ingress", "egress")


def process_name(agents: tuple[int, ...]) -> str:
    """An agent process's certificate name (its ACL subject): `agent-3`, or `agents-1-5` for an agent host."""
    return f"agent-{agents[0]}" if len(agents) == 1 else f"agents-{ids_runs_text(agents)}"


def processes(dep: Deployment, host: Host) -> list[str]:
    """The swarm's processes on a host, by certificate name (the observer is the launcher's, with the world)."""
    out = [process_name(g) for g in host.agent_processes]
    if dep.world_host == host.name:
        out += ["simworld", "observer"]
    if dep.monitor_host == host.name:
        out.append("monitor")
    return out


@dataclass
class _Rules:
    """Rules by id (each added once) and each process's rule ids."""

    run: str
    rules: dict[str, dict[str, Any]] = field(default_factory=dict)
    grants: dict[str, list[str]] = field(default_factory=dict)

    @property
    def r(self) -> str:
        return f"swarm/{self.run}"

    def rule(self, rid: str, messages: list[str], flows: tuple[str, ...], keys: list[str]) -> str:
        self.rules.setdefault(rid, {"id": rid, "messages": messages, "flows": list(flows), "permission": "allow",
                                    "key_exprs": keys})
        return rid

    def subscribe(self, rid: str, keys: list[str]) -> list[str]:
        """Declare a subscriber on keys (ingress) and receive the samples published there (egress)."""
        return [self.rule(f"{rid}-declare", ["declare_subscriber"], ("ingress",), keys),
                self.rule(f"{rid}-receive", ["put"], ("egress",), keys)]

    def publish(self, rid: str, keys: list[str], subscribed_as: list[str] | None = None) -> list[str]:
        """Put on keys (ingress), and learn of the subscribers there (egress): a client sends a sample only when
        the router has declared a matching subscriber to it. Declarations keep the subscriber's own key expression
        (`R/host/*/cmd`), hence subscribed_as."""
        return [self.rule(f"{rid}-put", ["put"], ("ingress",), keys),
                self.rule(f"{rid}-matching", ["declare_subscriber"], ("egress",), [*keys, *(subscribed_as or [])])]

    def membership(self, rid: str, token: str) -> list[str]:
        """Declare one's own liveliness token and follow everyone's (subscriber with history)."""
        r = self.r
        return [self.rule(f"{rid}-token", ["liveliness_token"], ("ingress",), [token]),
                self.rule(f"{rid}-follow", ["declare_liveliness_subscriber"], ("ingress",), [f"{r}/alive/**"]),
                self.rule(f"{rid}-tokens", ["liveliness_token"], ("egress",), [f"{r}/alive/**"])]

    def obstacle_reader(self, rid: str, also: list[str]) -> list[str]:
        """Subscribe the swarm's obstacle sets (and `also`) as an advanced subscriber: history queries to the
        publishers' caches, their replies, late publishers' liveliness."""
        obstacles = f"{self.r}/cell/*/agent/*/obstacles"
        return [*self.subscribe(f"{rid}-sub", [*also, obstacles]),
                self.rule(f"{rid}-history-query", ["query"], FLOWS, [f"{obstacles}/@adv/**"]),
                self.rule(f"{rid}-history-reply", ["reply"], ("egress",), [obstacles]),
                self.rule(f"{rid}-history-live", ["declare_liveliness_subscriber"], ("ingress",),
                          [f"{obstacles}/@adv/pub/**"])]

    def ros2_node(self, rid: str, domain: int, node: str, puts: str, subs: str) -> list[str]:
        """A ROS 2 node of rmw_zenoh: its data keys and its graph's liveliness tokens (node and entities)."""
        lv = f"@ros2_lv/{domain}/*/*/*/*/*/*/{node}"
        return [*self.publish(f"{rid}-ros2-pub", [puts]), *self.subscribe(f"{rid}-ros2-sub", [subs]),
                self.rule(f"{rid}-ros2-tokens", ["liveliness_token"], ("ingress",), [lv, f"{lv}/**"])]


def _agent(b: _Rules, i: int, group: tuple[int, ...], domain: int | None) -> list[str]:
    r, host = b.r, min(group)
    a, own = f"{r}/agent/{i}", f"{r}/cell/*/agent/{i}"
    beacons, obstacles = f"{r}/cell/*/host/*/beacons", f"{r}/cell/*/agent/*/obstacles"
    out = [
        *b.obstacle_reader("agents", [f"{r}/clock", beacons]),
        *b.publish(f"agent-{i}-pub", [f"{r}/host/{host}/cmd", f"{r}/cell/*/host/{host}/beacons", f"{own}/obstacles",
                                      f"{r}/report/agent-{i}"],
                   [f"{r}/host/*/cmd", beacons, obstacles, f"{r}/report/*"]),
        *b.subscribe(f"host-{host}-states", [f"{r}/host/{host}/state"]),
        b.rule(f"host-{host}-token", ["liveliness_token"], ("ingress",), [Keys(b.run).alive_host(group)]),
        *b.membership(f"agent-{i}", f"{r}/alive/agent/{i}"),
        # its advanced publisher's cache: a queryable under its own key, replies with its own set only
        b.rule(f"agent-{i}-cache", ["declare_queryable"], ("ingress",), [f"{own}/obstacles/@adv/pub/**"]),
        b.rule(f"agent-{i}-cache-reply", ["reply"], ("ingress",), [f"{own}/obstacles"]),
    ]
    if domain is not None:  # the plant's odometry replaces the state; its scan comes on the project's key
        out += [*b.ros2_node(f"agent-{i}", domain, f"agent_{i}", f"{domain}/robot_{i}/cmd_vel/**",
                             f"{domain}/robot_{i}/odom/**"),
                *b.subscribe(f"agent-{i}-scan", [f"{a}/scan"])]
    return out


def _simworld(b: _Rules, domain: int | None) -> list[str]:
    r = b.r
    out = [
        *b.publish("simworld-pub", [f"{r}/clock", f"{r}/truth", f"{r}/host/*/state", f"{r}/report/simworld"],
                   [f"{r}/report/*"]),
        *b.subscribe("simworld-sub", [f"{r}/host/*/cmd"]),
        *b.membership("simworld", f"{r}/alive/simworld"),
        # the truth's advanced publisher: its cache (a queryable, replies with the truth only) and heartbeats
        b.rule("simworld-truth-cache", ["declare_queryable"], ("ingress",), [f"{r}/truth/@adv/pub/**"]),
        b.rule("simworld-truth-reply", ["reply"], ("ingress",), [f"{r}/truth"]),
        *b.publish("simworld-truth-heartbeat", [f"{r}/truth/@adv/pub/**"]),
    ]
    if domain is not None:
        robots = f"{domain}/robot_$*"  # (`robot_*` is no key expression: `$*` within a chunk)
        out += [*b.ros2_node("simworld", domain, "simworld", f"{robots}/odom/**", f"{robots}/cmd_vel/**"),
                *b.publish("simworld-scan", [f"{r}/agent/*/scan"])]
    return out


def _monitor(b: _Rules, live_view: bool) -> list[str]:
    r = b.r
    out = [
        *b.publish("monitor-pub", [f"{r}/event"]),
        *b.subscribe("monitor-sub", [f"{r}/truth", f"{r}/clock", f"{r}/report/*"]),
        *b.membership("monitor", f"{r}/alive/monitor"),
        # recovery of a lost truth: the world's heartbeats, queries to its cache and their replies
        *b.subscribe("monitor-truth-heartbeat", [f"{r}/truth/@adv/pub/**"]),
        b.rule("monitor-truth-query", ["query"], FLOWS, [f"{r}/truth/@adv/**"]),
        b.rule("monitor-truth-reply", ["reply"], ("egress",), [f"{r}/truth"]),
    ]
    if live_view:  # monitor/live.py: an advanced subscriber on every agent's obstacle set
        out += b.obstacle_reader("monitor-live", [])
    return out


def _all_processes(dep: Deployment) -> tuple[_Rules, dict[str, list[str]]]:
    """Every process of the deployment with its rule ids."""
    b = _Rules(dep.run)
    group_of = {i: g for h in dep.hosts for g in h.agent_processes for i in g}  # (its host's key: the lowest id)
    per_agent = {i: _agent(b, i, group_of[i], dep.ros2_domain) for i in dep.agent_ids}
    grants: dict[str, list[str]] = {}
    for h in dep.hosts:
        for g in h.agent_processes:
            grants[process_name(g)] = list(dict.fromkeys(rid for i in g for rid in per_agent[i]))
    grants["simworld"] = _simworld(b, dep.ros2_domain)
    grants["monitor"] = _monitor(b, dep.live_view)
    grants["observer"] = b.subscribe("observer-sub", [f"{b.r}/clock", f"{b.r}/event"])
    return b, grants


def _onward(b: _Rules, rid: str) -> str | None:
    """What one of our processes may send (an ingress rule), the router may forward to another host's router
    (egress); None for a rule of what it receives."""
    rl = b.rules[rid]
    if "ingress" not in rl["flows"]:
        return None
    return b.rule(f"{rid}~onward", rl["messages"], ("egress",), rl["key_exprs"])


def router_acl(dep: Deployment, host: Host) -> dict[str, Any]:
    """The access control of host's router: deny by default; its own processes by certificate; each other host's
    router granted what the other hosts' processes may do and what ours may send their way (queryables and
    tokens included: a router learns them from its neighbours)."""
    b, grants = _all_processes(dep)
    ours = processes(dep, host)
    theirs = [p for h in dep.hosts if h.name != host.name for p in processes(dep, h)]
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []

    def grant(subject: str, rule_ids: list[str]) -> None:
        subjects.append({"id": subject, "cert_common_names": [subject]})
        policies.append({"id": f"{subject}-policy", "rules": list(dict.fromkeys(rule_ids)), "subjects": [subject]})

    for p in ours:
        grant(p, grants[p])
    if theirs:
        crossing = [rid for p in theirs for rid in grants[p]]
        crossing += [o for p in ours for rid in grants[p] if (o := _onward(b, rid)) is not None]
        for h in dep.hosts:
            if h.name != host.name:
                grant(h.router_name, crossing)
    used = {rid for pol in policies for rid in pol["rules"]}
    return {"enabled": True, "default_permission": "deny", "rules": [rl for rid, rl in b.rules.items() if rid in used],
            "subjects": subjects, "policies": policies}
