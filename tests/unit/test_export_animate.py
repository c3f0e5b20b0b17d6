"""`monitor export --format mcap` and `monitor animate` on a short in-process paper run, read back with
independent readers: the `mcap` package's reader with its protobuf decoder (the schemas the file carries),
and Pillow for the GIF. Expected values come from the run record and the scenario (docs/foxglove.md), not
from the exporter."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from PIL import Image
from typer.testing import CliRunner

from reconswarm.record.store import RunRecord
from reconswarm.record.summary import summarize
from reconswarm.scenario.model import load, parse, to_toml
from reconswarm_bringup.cli import app
from reconswarm_bringup.engine import SimConfig, run

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "deploy" / "scenarios" / "paper.toml"
DURATION_S = 25.0  # two merges (6.5 s and 21.05 s) happen before


@pytest.fixture(scope="module")
def short_run(tmp_path_factory) -> Path:
    base = load(PAPER)
    s = parse(to_toml(replace(base, meta=replace(base.meta, duration_s=DURATION_S))), str(PAPER))
    out = tmp_path_factory.mktemp("short")
    run(SimConfig(s, out))
    return out / "run.db"


def cli(*args: str):
    return CliRunner().invoke(app, list(args))


def read_all(path: Path):
    """Every message by topic as (log_time, publish_time, decoded), plus the summary, attachments, metadata."""
    dec = DecoderFactory()
    by_topic: dict[str, list] = {}
    with path.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        for schema, channel, msg in reader.iter_messages(log_time_order=False):
            if channel.message_encoding == "json":
                body = json.loads(msg.data)
            else:
                decode = dec.decoder_for(channel.message_encoding, schema)
                assert decode is not None, channel.topic
                body = decode(msg.data)
            by_topic.setdefault(channel.topic, []).append((msg.log_time, msg.publish_time, body))
        attachments = list(reader.iter_attachments())
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    return summary, by_topic, attachments, metadata


def yaw(q) -> float:
    return 2 * math.atan2(q.z, q.w)


def test_mcap_export_reads_back(short_run, tmp_path):
    out = tmp_path / "run.mcap"
    r = cli("monitor", "export", str(short_run), "--format", "mcap", "-o", str(out))
    assert r.exit_code == 0, r.output
    rec = RunRecord(short_run)
    tk, events, s = rec.ticks(), rec.events(), rec.scenario
    expect = summarize(rec)
    start_ns = int(Decimal(rec.meta["started_unix"]) * 10**9)
    rec.close()
    n = tk.t.size
    assert n == round(DURATION_S / s.meta.dt_s) + 1
    assert len(events) == 2  # the run holds events to export

    summary, msgs, attachments, metadata = read_all(out)
    topics = {c.topic: (summary.schemas[c.schema_id].name, summary.schemas[c.schema_id].encoding, c.message_encoding)
              for c in summary.channels.values()}
    assert topics == {"/world": ("foxglove.SceneUpdate", "protobuf", "protobuf"),
                      "/swarm": ("foxglove.SceneUpdate", "protobuf", "protobuf"),
                      "/events": ("foxglove.Log", "protobuf", "protobuf"),
                      "/tracking_error": ("reconswarm.TrackingError", "jsonschema", "json"),
                      "/metrics": ("reconswarm.Metrics", "jsonschema", "json")}
    counts = {topic: len(v) for topic, v in msgs.items()}
    assert counts == {"/swarm": n, "/tracking_error": n, "/metrics": n, "/events": len(events),
                      "/world": math.floor(DURATION_S) + 1}  # every tick; the world once per simulated second
    stats = summary.statistics
    assert stats.message_count == sum(counts.values())

    # Times: the run's wall-clock start plus simulated time, in ns; not 1970.
    times = sorted(m[0] for m in msgs["/swarm"])
    assert times == [start_ns + round(float(t) * 1e9) for t in tk.t]
    assert times[0] > 1_600_000_000 * 10**9
    assert all(m[0] == m[1] for ms in msgs.values() for m in ms)  # publish time = log time
    assert sorted(m[0] for m in msgs["/events"]) == [start_ns + round(e["t"] * 1e9) for e in events]
    for (_, _, log), e in zip(sorted(msgs["/events"], key=lambda m: m[0]), events, strict=True):
        assert log.message.startswith(f"{e['kind']} at t = {e['t']:.2f} s")
        assert log.timestamp.seconds * 10**9 + log.timestamp.nanos == start_ns + round(e["t"] * 1e9)

    # The scenario TOML attached, the run's summary as metadata.
    assert [(a.name, a.media_type) for a in attachments] == [("scenario.toml", "application/toml")]
    assert parse(attachments[0].data.decode()) == s
    meta = metadata["run"]
    assert (meta["scenario"], meta["planner"], meta["mode"]) == ("paper", "reconfigurable", "inprocess")
    assert meta["converged"] == "false" and meta["agents"] == "10"
    assert int(meta["merges"]) == expect["merges"] == 2 and int(meta["splits"]) == expect["splits"]
    assert int(meta["start_time_ns"]) == start_ns

    slots = np.asarray(s.target_m) + s.offsets
    swarm = sorted(msgs["/swarm"], key=lambda m: m[0])
    errs = sorted(msgs["/tracking_error"], key=lambda m: m[0])
    for row in (0, n // 3, 2 * n // 3, n - 1):
        upd = swarm[row][2]
        agents = {e.id: e for e in upd.entities if e.id.startswith("agent/")}
        assert len(agents) == 10
        assert [d.type for d in upd.deletions] == [1]  # ALL: each update replaces the previous one
        groups = set()
        for k, aid in enumerate(s.ids):
            e = agents[f"agent/{aid}"]
            (disc,), (arrow,) = e.cylinders, e.arrows
            assert (disc.pose.position.x, disc.pose.position.y) == (tk.px[row, k], tk.py[row, k])
            assert disc.size.x == disc.size.y == pytest.approx(2 * s.radii[k])
            assert (arrow.pose.position.x, arrow.pose.position.y) == (tk.px[row, k], tk.py[row, k])
            assert math.remainder(yaw(arrow.pose.orientation) - tk.theta[row, k], 2 * math.pi) == pytest.approx(0)
            assert e.texts[0].text == str(aid)
            groups.add((disc.color.r, disc.color.g, disc.color.b))
        assert len(groups) == tk.groups[row]  # one colour per group, as many as the record counts
        # Links: every pair within the link range is one; none beyond range + hysteresis (2 m).
        p = np.stack([tk.px[row], tk.py[row]], axis=1)
        d = np.linalg.norm(p[:, None] - p[None], axis=2)
        link_ent = [e for e in upd.entities if e.id == "links"]
        pts = [(q.x, q.y) for q in link_ent[0].lines[0].points] if link_ent else []
        index = {(float(x), float(y)): k for k, (x, y) in enumerate(p)}
        pairs = {tuple(sorted((index[pts[i]], index[pts[i + 1]]))) for i in range(0, len(pts), 2)}
        within = {(i, j) for i in range(10) for j in range(i + 1, 10) if d[i, j] <= s.planner.link_range_m}
        assert within <= pairs
        assert all(d[i, j] <= s.planner.link_range_m + 2.0 for i, j in pairs)
        # Tracking error per agent: ‖p_i - (p* + Δ_i)‖.
        msg = errs[row][2]
        for k, aid in enumerate(s.ids):
            assert msg[f"agent_{aid}"] == pytest.approx(math.hypot(*(p[k] - slots[k])), abs=1e-9)
        assert msg["max_m"] == pytest.approx(tk.max_error_m[row], abs=1e-9)

    world = msgs["/world"][0][2]
    ids = sorted(e.id for e in world.entities)
    assert ids == sorted([*(f"obstacle/{o.id}" for o in s.obstacles), "slots", "target"])
    spheres = next(e for e in world.entities if e.id == "slots").spheres
    assert sorted((q.pose.position.x, q.pose.position.y) for q in spheres) == sorted(map(tuple, slots.tolist()))
    for k, o in enumerate(s.obstacles):
        ent = next(e for e in world.entities if e.id == f"obstacle/{o.id}")
        ring = [(q.x, q.y) for q in ent.lines[0].points]
        assert ring == [tuple(v) for v in s.polygon(k).tolist()]
        tri = ent.triangles[0].points
        assert len(tri) == 3 * (len(ring) - 2)  # a fan over the convex polygon


def test_mcap_export_period(short_run, tmp_path):
    out = tmp_path / "sampled.mcap"
    r = cli("monitor", "export", str(short_run), "--format", "mcap", "-o", str(out), "--period", "0.5")
    assert r.exit_code == 0, r.output
    _, msgs, _, _ = read_all(out)
    t = sorted(m[2]["t_s"] for m in msgs["/tracking_error"])
    assert len(msgs["/swarm"]) == len(t) == math.floor(DURATION_S / 0.5) + 1
    assert max(np.diff(t)) == pytest.approx(0.5)


def test_animation_frame_count(short_run, tmp_path):
    out = tmp_path / "run.gif"
    r = cli("monitor", "animate", str(short_run), "-o", str(out), "--fps", "4", "--speed", "10", "--dpi", "30")
    assert r.exit_code == 0, r.output
    with Image.open(out) as im:
        assert im.format == "GIF"
        # a frame every speed / fps simulated seconds
        assert getattr(im, "n_frames", 1) == math.floor(DURATION_S * 4 / 10) + 1
        assert im.info["duration"] == 250  # 1 / fps


@pytest.mark.parametrize(("args", "says"), [
    (["export", "{db}", "--format", "xml", "-o", "{tmp}/a.xml"], "--format"),
    (["export", "{db}", "--format", "mcap"], "-o FILE.mcap"),
    (["export", "{tmp}/missing.db", "--format", "mcap", "-o", "{tmp}/a.mcap"], "missing.db"),
    (["export", "{tmp}/not-a-record.db", "--format", "mcap", "-o", "{tmp}/a.mcap"], "not-a-record.db"),
    (["export", "{db}", "--format", "mcap", "-o", "{tmp}/not-a-record.db/a.mcap"], "a.mcap: cannot write"),
    (["export", "{db}", "--format", "mcap", "-o", "{tmp}/a.mcap", "--period", "1.5"], "--period"),
    (["animate", "{db}", "-o", "{tmp}/a.avi"], "a.avi"),
    (["animate", "{db}", "-o", "{tmp}/not-a-record.db/a.gif"], "a.gif: cannot write"),
    (["animate", "{tmp}/missing.db", "-o", "{tmp}/a.gif"], "missing.db"),
    (["animate", "{db}", "-o", "{tmp}/a.gif", "--fps", "0"], "--fps"),
    (["animate", "{db}", "-o", "{tmp}/a.gif", "--speed", "0"], "--speed"),
    (["animate", "{db}", "-o", "{tmp}/a.mp4"], "ffmpeg"),
])
def test_bad_requests_exit_2_with_one_line(short_run, tmp_path, monkeypatch, args, says):
    monkeypatch.setenv("PATH", "")  # no ffmpeg
    (tmp_path / "not-a-record.db").write_bytes(b"hello")
    r = cli("monitor", *[a.format(db=short_run, tmp=tmp_path) for a in args])
    assert r.exit_code == 2, r.output
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert says in lines[0], lines[0]
    assert not list(tmp_path.glob("a.*"))  # nothing written


def test_scene_sampling_stays_within_budget_and_at_least_once_a_second():
    from monitor.mcap_export import AGENT_SCENES_BUDGET, choose_period, sampled_rows

    t = np.arange(11629) * 0.05  # a generated 100-agent mission of 581.4 s
    assert choose_period(10, t[:4446], None) is None  # the paper run: every tick
    # 0.1 s would draw 100 x 5815 agents, over the budget; 0.2 s draws 100 x 2908.
    assert 100 * 5815 > AGENT_SCENES_BUDGET >= 100 * 2908
    assert choose_period(100, t, None) == 0.2
    assert sampled_rows(t, 0.1).size == 5815 and sampled_rows(t, 0.2).size == 2908  # 581.4 / period + 1
    assert choose_period(100_000, t, None) == 1.0  # never sparser than once a simulated second
    assert choose_period(100_000, t, 0.05) == 0.05  # the caller's choice wins
