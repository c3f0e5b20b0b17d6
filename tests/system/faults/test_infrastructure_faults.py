"""The monitor killed, the router restarted, 10,000 malformed messages: the mission goes on, the record holds.

The monitor and router faults concern the infrastructure, not the paper's geometry: they run the paper's first
three agents without obstacles (tests/system/faults/test_router_loss.py `three_agents`: converged at 172.05 s,
in a fraction of the paper's wall time). The flood's fan-out counts are the paper's ten agents, on the paper's
first leg (tests.support.short_paper)."""

from __future__ import annotations

import json
from pathlib import Path

from tests.support import faults_log, reconswarm, run_launcher, short_paper, summary
from tests.system.faults.test_router_loss import three_agents


def test_monitor_killed_is_restarted_and_appends(tmp_path: Path, out: Path) -> None:
    p = run_launcher(out, "-s", str(three_agents(tmp_path)), "--fault", "kill:monitor@80", "--json")
    assert p.returncode == 0, p.stderr[-3000:]
    s = json.loads(p.stdout)
    assert s["converged"] and s["collisions"] == 0
    (_, kill_t, _), = faults_log(out)
    gaps = s["record_gaps"]
    assert len(gaps) == 1
    # At most 1 s of simulated time is lost before the kill; the restarted monitor notes the gap.
    assert gaps[0]["t_from"] >= kill_t - 1.0 and gaps[0]["t_to"] > gaps[0]["t_from"]
    assert s["duration_s"] == s["convergence_time_s"]  # recorded to the end by the second monitor
    assert len((out / "logs" / "monitor.log").read_text().split("monitor up")) == 3  # two incarnations


def test_router_restarted(tmp_path: Path, out: Path) -> None:
    p = run_launcher(out, "-s", str(three_agents(tmp_path)), "--fault", "restart:router@90+2", "--json")
    assert p.returncode == 0, p.stderr[-3000:]
    s = json.loads(p.stdout)
    assert s["converged"] and s["collisions"] == 0 and s["agents_lost"] == []
    assert s["convergence_time_s"] <= 190  # (172.05 s undisturbed)
    # What was in flight when the router went is lost: the record claims the engine's path only if it kept it.
    # Every agent's link went mid-mission, so each says its next tick was a guess, from the restart on.
    restart_t = faults_log(out)[0][1]
    assert s["deterministic"] is False and restart_t <= s["determinism_lost_at_s"] <= restart_t + 10.0, s


def test_flood_of_malformed_messages(tmp_path: Path, out: Path) -> None:
    scen = short_paper(tmp_path)
    p = run_launcher(out, "-s", str(scen), "--fault", "flood@30", "--json")
    assert p.returncode == 0, p.stderr[-3000:]
    s = json.loads(p.stdout)
    assert s["converged"] and s["collisions"] == 0 and s["agents_lost"] == []
    # Malformed input changes nothing: lockstep stays on the engine's path. The flood swamps the agents' cell
    # subscriptions, yet each agent's host hands it a peer's beacon of the tick before no later than its own state
    # (reconswarm/net/runtime/inbox.py `ordered`: the link's order), so no wait set misses a peer closing in.
    firsts = [next(line for line in f.read_text().splitlines() if "no longer deterministic" in line)
              for f in sorted((out / "logs").glob("agent-*.log")) if "no longer deterministic" in f.read_text()]
    assert s["deterministic"] is True and not firsts, (s["determinism_lost_at_s"], firsts)
    ref = json.loads(reconswarm("sim", str(scen), "-o", str(tmp_path / "sim"), "--json").stdout)
    assert s["convergence_time_s"] == ref["convergence_time_s"] == 156.3, ref
    sent = json.loads((out / "logs" / "flood.log").read_text().strip().splitlines()[-1])
    assert sent["total"] == 10_000
    # One payload in 8 is over the wire's limit: the run's router forwards none of them (PAYLOAD_CAP), so
    # nobody receives them. Who receives each of the others (agents never receive their own announcements,
    # but do check anyone else's): beacons and obstacle sets go under a cell (the one the flood heard each
    # agent in): an agent hears only the cells around it, so between none and all 10 agents receive them; the
    # monitor hears no beacons.
    assert 1000 < sum(sent["over_limit"].values()) < 1600, sent["over_limit"]
    sent_by: dict[str, int] = {}
    for key, n in sent["sent"].items():
        leaf = key.rsplit("/", 1)[1]
        sent_by[leaf] = sent_by.get(leaf, 0) + n - sent["over_limit"].get(key, 0)
    fixed = {"clock": 10 + 1, "truth": 1, "event": 0, "state": 1, "cmd": 1}
    lowest = sum(n * fixed[k] for k, n in sent_by.items() if k in fixed)
    highest = lowest + sent_by["beacons"] * 10 + sent_by["obstacles"] * 10
    # Every delivery is dropped and counted exactly once, as rejected (it does not decode); none is an
    # intrusion (the flood's only ones were its payloads over 1 MiB on obstacle-set keys, which the router
    # keeps back). Exactly so where the fan-out is known:
    by = s["messages_rejected_by_process"]
    assert by["monitor"] == sent_by["clock"] + sent_by["truth"], by
    assert by["simworld"] == sent_by["cmd"], by
    assert s["intrusions"] == 0, s["intrusions_by_kind"]
    got = s["messages_rejected"]
    assert lowest < got <= highest, (by, lowest, highest)  # (agents did receive cell keys)
    again = summary(out / "run.db")
    assert again["messages_rejected"] == got and again["intrusions"] == 0
