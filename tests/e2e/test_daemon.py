"""End to end: ``fcsod run`` and ``fcsod subscribe`` as separate processes on loopback zenoh, real job folders."""

from __future__ import annotations

import hashlib
import json
import shutil
import sqlite3
from pathlib import Path

import pytest
import trimesh
from mcap.reader import make_reader

from fcsod.cli import main
from fcsod.record.recorder import ALWAYS_RECORDED, DESIGN_RECORDED, TOPIC_BUS, TOPIC_LOG, TOPIC_STATE, read_record
from tests.broken_meshes import sheet_stl
from tests.conftest import HANG_GUARD_S
from tests.fcsod_helpers import (
    DATA,
    Process,
    drop_job,
    finished,
    foxglove_messages,
    free_port,
    start_daemon,
    start_subscriber,
    write_config,
)

CUBE = DATA / "20mm-xyz-cube.stl"


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    """A running daemon and a subscriber connected to it before any job."""
    base = tmp_path_factory.mktemp("cell")
    port = free_port()
    config = write_config(base, port)
    daemon = start_daemon(config)
    subscriber = start_subscriber(config, save=base / "received")
    yield {"base": base, "config": config, "daemon": daemon, "subscriber": subscriber, "port": port}
    subscriber.stop()
    assert daemon.stop() == 0, "daemon did not stop cleanly on SIGTERM"


@pytest.fixture(scope="module")
def cube_job(cell) -> str:
    """The id of a plain cube job (no manifest) the daemon has done."""
    drop_job(cell["base"] / "watch" / "cube", {"cube.stl": CUBE})
    done = finished(cell["subscriber"], "cube")
    assert done["body"]["state"] == "done", done
    return done["job_id"]


def _audit(capsys, *args: str) -> tuple[int, str]:
    """Run ``fcsod audit`` (in this process) and return its exit code and output."""
    code = main(["audit", *args])
    return code, capsys.readouterr().out


def test_job_written_slowly_is_designed_published_and_recorded(cell, capsys):
    """The issue's end-to-end check: readiness, every zenoh topic, outputs, MCAP channels, audit --verify."""
    base, subscriber = cell["base"], cell["subscriber"]
    manifest = (
        '[[parts]]\nfile = "parts/cube.stl"\nunits = "mm"\nquantity = 3\n\n[poses]\ncount = '
        "1\n\n[gripper]\nmax_opening_mm = 45\n"
    )
    folder = base / "watch" / "batch-slow"
    # manifest first, then the part in two halves: pauses far below settle_seconds (0.7 s), so the
    # folder never looks settled before it is complete (readiness itself: test_fcsod_jobs, clock stepped)
    drop_job(folder, {"job.toml": manifest, "parts/cube.stl": CUBE}, pause_s=0.1)
    done = finished(subscriber, "batch-slow")
    assert done["body"]["state"] == "done", done
    job_id = done["job_id"]
    lines = [v for v in subscriber.json_lines() if v.get("job_id") == job_id and v.get("source") == "live"]
    states = [v["body"]["state"] for v in lines if v["topic"] == "status"]
    assert states == ["queued", "running", "done"]
    topics = {v["topic"] for v in lines}
    assert {"status", "quality", "grasps", "design", "placement"} <= topics

    # readiness: the job did not start while the part was still being written
    daemon_lines = cell["daemon"].json_lines()
    queued = next(v for v in daemon_lines if v.get("message") == "job queued" and v.get("job_id") == job_id)
    assert queued["inputs"] == 2

    quality = next(v for v in lines if v["topic"] == "quality")["body"]
    assert 0 < quality["quality"] <= 1.05 and quality["quality_measure"] == "capture"
    assert quality["finger_watertight"] is True
    grasps = next(v for v in lines if v["topic"] == "grasps")["body"]["grasps"]
    assert grasps and grasps[0]["part"] == "cube" and len(grasps[0]["quaternion_wxyz"]) == 4
    design = next(v for v in lines if v["topic"] == "design")
    assert design["encoding"] == "model/stl"
    assert design["attachment"]["job_id"] == job_id and design["sha256_ok"] is True
    received = Path(design["saved"]).read_bytes()
    assert hashlib.sha256(received).hexdigest() == design["attachment"]["sha256"]
    mesh = trimesh.load(trimesh.util.wrap_as_stream(received), file_type="stl")
    mesh.merge_vertices()
    assert mesh.is_watertight and mesh.volume > 0

    out = base / "out" / job_id
    for name in ("finger.stl", "fingerpad.stl", "build.3mf", "report.json", "job.mcap"):
        assert (out / name).is_file(), name
    assert (out / "finger.stl").read_bytes() == received
    assert json.loads((out / "report.json").read_text())["settings"]["gripper"]["max_opening_mm"] == 45
    assert not list((base / "out").glob(".tmp-*"))
    assert sorted(p.name for p in folder.rglob("*")) == ["cube.stl", "job.toml", "parts"], (
        "the daemon wrote into the job folder"
    )

    with open(out / "job.mcap", "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        channels = {c.topic: c for c in summary.channels.values()}
        schemas = summary.schemas
        assert set(ALWAYS_RECORDED) | set(DESIGN_RECORDED) <= set(channels)
        for channel in channels.values():
            # JSON channels, plus the ROS 2 form of the published messages for ros2 bag play
            # ... and foxglove-sdk's protobuf scene and frames
            expected = (
                ("cdr", "ros2msg")
                if channel.topic.startswith("/fcsod/")
                else ("protobuf", "protobuf")
                if channel.topic in ("/scene", "/tf")
                else ("json", "jsonschema")
            )
            assert (channel.message_encoding, schemas[channel.schema_id].encoding) == expected, channel.topic
        # ROS 2 topics named as the zenoh keys: ~/plan the pick plan, ~/placement the build placement, and what a
        # PoseArray cannot carry (job id, approach opening, verdict) on ~/grasp_details
        assert {t for t in channels if t.startswith("/fcsod/")} == {
            "/fcsod/grasps",
            "/fcsod/grasp_details",
            "/fcsod/placement",
            "/fcsod/plan",
            "/fcsod/quality",
            "/fcsod/status",
        }
        assert schemas[channels["/scene"].schema_id].name == "foxglove.SceneUpdate"
        counts = summary.statistics.channel_message_counts
        assert all(counts[c.id] > 0 for c in channels.values())
        chunk_compression = {index.compression for index in summary.chunk_indexes}
        assert chunk_compression == {"zstd"}
    record = read_record(out / "job.mcap")
    assert not record.truncated
    assert [s["state"] for s in record.of(TOPIC_STATE)] == ["queued", "running", "done"]
    published = [b["key_expr"].rsplit("/", 1)[-1] for b in record.of(TOPIC_BUS)]
    assert published == ["status", "quality", "grasps", "design", "plan", "placement", "status"]
    assert any(b.get("stage") == "screening" for b in record.of(TOPIC_LOG))
    scene = foxglove_messages(out / "job.mcap")["/scene"][0]
    assert len(scene["entities"][0]["triangles"]) == 5

    code, text = _audit(capsys, str(out / "job.mcap"), "--verify", str(out), "--inputs", str(folder))
    assert code == 0, text
    assert "record check passed" in text and "state done" in text and "TRUNCATED" not in text
    # a tampered output is caught
    tampered = base / "tampered"
    shutil.copytree(out, tampered)
    (tampered / "fingerpad.stl").write_bytes(b"solid x\nendsolid x\n")
    code, text = _audit(capsys, str(tampered / "job.mcap"), "--verify", str(tampered))
    assert code == 1 and "PROBLEM: output" in text and "fingerpad.stl" in text


def test_same_job_dropped_twice_runs_once(cell, cube_job):
    base, subscriber, daemon = cell["base"], cell["subscriber"], cell["daemon"]
    folder, job_id = base / "watch" / "cube", cube_job
    # the same folder again, same content, new files and mtimes
    shutil.rmtree(folder)
    drop_job(folder, {"cube.stl": CUBE})
    daemon.wait_for(
        lambda v: (
            isinstance(v, dict) and v.get("message") == "job already known: not run again" and v.get("job_id") == job_id
        )
    )
    started = [v for v in daemon.json_lines() if v.get("message") == "job started" and v.get("job_id") == job_id]
    assert len(started) == 1
    done = [
        v
        for v in subscriber.json_lines()
        if v.get("job_id") == job_id and v.get("topic") == "status" and v["body"]["state"] == "done"
    ]
    assert len(done) == 1
    with sqlite3.connect(base / "state" / "journal.sqlite3") as db:
        assert db.execute("SELECT state, attempt FROM jobs WHERE job_id = ?", (job_id,)).fetchall() == [("done", 1)]


def test_bad_jobs_fail_clearly_and_the_next_good_job_runs(cell):
    base, subscriber = cell["base"], cell["subscriber"]
    # the daemon repairs by default: only a file that encloses no volume fails
    drop_job(base / "watch" / "open-mesh", {"top_face.stl": sheet_stl(DATA / "20mm-xyz-cube.stl")})
    drop_job(
        base / "watch" / "unknown-key", {"job.toml": "[sampler]\nlength_mm = 10\nlenght_mm = 12\n", "cube.stl": CUBE}
    )
    drop_job(base / "watch" / "escape", {"job.toml": '[[parts]]\nfile = "../cube/cube.stl"\n', "cube.stl": CUBE})
    drop_job(base / "watch" / "good-after-bad", {"cube.stl": CUBE})

    open_mesh = finished(subscriber, "open-mesh")["body"]
    assert open_mesh["state"] == "failed"
    assert "top_face.stl" in open_mesh["error"] and "open mesh" in open_mesh["error"]
    assert "even after --repair no shell encloses a volume" in open_mesh["error"]
    unknown = finished(subscriber, "unknown-key")["body"]
    assert unknown["state"] == "failed"
    assert "job.toml" in unknown["error"] and "sampler.lenght_mm: unknown key" in unknown["error"]
    escape = finished(subscriber, "escape")["body"]
    assert escape["state"] == "failed" and "leaves the job folder" in escape["error"]
    assert finished(subscriber, "good-after-bad")["body"]["state"] == "done"

    for body in (open_mesh, unknown, escape):
        out = base / "out" / body["job_id"]
        assert sorted(p.name for p in out.iterdir()) == ["job.mcap"], "a failed job leaves its record and nothing else"
        record = read_record(out / "job.mcap")
        assert not record.truncated
        last_state = record.of(TOPIC_STATE)[-1]
        assert (last_state["state"], last_state["error"]) == ("failed", body["error"])
        assert json.loads(record.of(TOPIC_BUS)[-1]["payload_text"])["error"] == body["error"]
        assert any(line["level"] == "error" and line["message"] == body["error"] for line in record.of(TOPIC_LOG))


def test_job_with_an_ungraspable_part_is_delivered_with_a_warning(cell):
    base, subscriber = cell["base"], cell["subscriber"]
    # lying flat (pose 0) the 52 x 70 mm plug is wider than the 50 mm opening every way
    manifest = '[poses]\ncount = 1\nselect = [0]\n[[parts]]\nfile = "cube.stl"\n[[parts]]\nfile = "plug.stl"\n'
    drop_job(
        base / "watch" / "with-plug", {"job.toml": manifest, "cube.stl": CUBE, "plug.stl": DATA / "capsela200_plug.stl"}
    )
    done = finished(subscriber, "with-plug")["body"]
    assert done["state"] == "done", done
    assert any("plug in stable pose 0 cannot be grasped" in w for w in done["warnings"]), done["warnings"]
    report = json.loads((base / "out" / done["job_id"] / "report.json").read_text())
    assert [u["part"] for u in report["ungraspable"]] == ["plug"]
    assert [g["part"] for g in report["grasps"]] == ["cube"]


def test_late_subscriber_gets_results_from_the_queryable(cell, cube_job):
    base, job_id = cell["base"], cube_job
    late = start_subscriber(cell["config"], save=base / "late")
    try:

        def replies() -> dict:
            return {
                v["topic"]: v for v in late.json_lines() if v.get("source") == "query" and v.get("job_id") == job_id
            }

        # the replies need not arrive in the journal's order (zenoh consolidates them): wait for all five
        late.wait_for(lambda v: set(replies()) == {"status", "quality", "grasps", "design", "plan", "placement"})
        got = replies()
        assert got["design"]["sha256_ok"] is True
        assert got["status"]["body"]["state"] == "done"
        assert Path(got["design"]["saved"]).read_bytes() == (base / "out" / job_id / "finger.stl").read_bytes()
    finally:
        late.stop()


def test_replay_publishes_the_recorded_messages(cell, cube_job):
    job_id = cube_job
    record = cell["base"] / "out" / job_id / "job.mcap"
    port = free_port()
    replay = Process(
        [
            "replay",
            str(record),
            "--config",
            str(cell["config"]),
            "--listen",
            f"tcp/127.0.0.1:{port}",
            "--wait",
            str(HANG_GUARD_S),
        ]
    )
    listener = Process(
        [
            "subscribe",
            "--config",
            str(cell["config"]),
            "--connect",
            f"tcp/127.0.0.1:{port}",
            "--no-query",
            "--exit-after",
            "1",
            "--timeout",
            str(HANG_GUARD_S),
        ]
    )
    try:
        done = listener.wait_for(
            lambda v: isinstance(v, dict) and v.get("topic") == "status" and v["body"]["state"] == "done"
        )
        assert done["job_id"] == job_id
        assert replay.popen.wait(timeout=HANG_GUARD_S) == 0
        topics = [v["topic"] for v in listener.json_lines() if v.get("job_id") == job_id]
        assert topics == ["status", "quality", "grasps", "design", "plan", "placement", "status"]
    finally:
        listener.stop()
        replay.stop()
