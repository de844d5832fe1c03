"""fcsod with [verify]: the design is done and published first, its verification follows on zenoh, in the journal and in
MCAP.
"""

from __future__ import annotations

import json

from examples.sim_parts import ridged_block
from fcsod.record.recorder import (
    TOPIC_BUS,
    TOPIC_VERIFICATION,
    TOPIC_VERIFICATION_SCENE,
    VERIFICATION_RECORD_NAME,
    read_record,
)
from tests.fcsod_helpers import drop_job, finished, free_port, start_daemon, start_subscriber, write_config

MANIFEST = '[[parts]]\nfile = "ridged.stl"\n\n[sampler]\nyaw_deg = [0]\n'


def test_done_job_is_verified_published_recorded_and_answered(tmp_path):
    port = free_port()
    config = write_config(tmp_path, port, verify="enabled = true\ntop_k = 0\ntrials = 2")
    part = tmp_path / "ridged.stl"
    ridged_block().export(part)
    daemon = start_daemon(config)
    subscriber = start_subscriber(config)
    try:
        drop_job(tmp_path / "watch" / "ridged", {"job.toml": MANIFEST, "ridged.stl": part})
        done = finished(subscriber, "ridged")
        assert done["body"]["state"] == "done", done
        job_id = done["job_id"]
        message = subscriber.wait_for(
            lambda v: isinstance(v, dict) and v.get("topic") == "verification" and v["job_id"] == job_id, 120
        )
        lines = [v for v in subscriber.json_lines() if v.get("job_id") == job_id]
        # the verification follows the done status
        topics = [v["topic"] for v in lines]
        assert topics.index("verification") > max(i for i, v in enumerate(lines) if v["topic"] == "status")
        body = message["body"]
        assert body["file"] == "verification.json" and len(body["scenarios"]) == 1
        scenario = body["scenarios"][0]
        # the carved V-grooves centre the ridged block; flat pads cannot
        assert scenario["success_rate"] == 1.0 and scenario["flat_success_rate"] < 1.0

        out = tmp_path / "out" / job_id
        verification = json.loads((out / "verification.json").read_text())
        assert verification["scenarios"][0]["fcso"]["success_rate"] == scenario["success_rate"]
        assert "<!-- fcso verify -->" in (out / "report.html").read_text()
        record = read_record(out / VERIFICATION_RECORD_NAME)
        assert record.of(TOPIC_VERIFICATION)[0]["passed"] == body["passed"]
        scenes = record.of(TOPIC_VERIFICATION_SCENE)
        assert len(scenes) > 10 and scenes[0]["entities"][0]["triangles"]
        assert any(b["key_expr"].endswith("/verification") for b in record.of(TOPIC_BUS))

        # a late joiner gets it from the journal's queryable
        late = start_subscriber(config)
        try:
            answered = late.wait_for(
                lambda v: isinstance(v, dict) and v.get("topic") == "verification" and v["job_id"] == job_id, 30
            )
            assert answered["source"] != "live" and answered["body"] == body
        finally:
            late.stop()
    finally:
        subscriber.stop()
        assert daemon.stop() == 0


SETS_MANIFEST = """
[[parts]]
file = "narrowing.stl"

[[parts]]
file = "widening.stl"

[finger_sets]
min_retained = 0.7

[verify]
enabled = true
top_k = 0
trials = 2
"""


def test_every_finger_set_of_a_job_is_verified_into_its_folder_and_on_its_key(tmp_path):
    # the conflicting knob parts of tests/fcso/test_sets.py need two fingers at min_retained 0.7
    from tests.fcso.test_sets import NARROWING, WIDENING

    port = free_port()
    config = write_config(tmp_path, port)
    files = {}
    for part in (NARROWING, WIDENING):
        files[f"{part.name}.stl"] = tmp_path / f"{part.name}.stl"
        part.mesh.export(files[f"{part.name}.stl"])
    daemon = start_daemon(config)
    subscriber = start_subscriber(config)
    try:
        drop_job(tmp_path / "watch" / "knobs", {"job.toml": SETS_MANIFEST, **files})
        done = finished(subscriber, "knobs", timeout=180)
        assert done["body"]["state"] == "done", done
        job_id = done["job_id"]
        subscriber.wait_for(
            lambda v: (
                isinstance(v, dict)
                and v.get("topic") == "verification/2"
                and v["job_id"] == job_id
                and v.get("signature_ok")
            ),
            240,
        )
        messages = {v["topic"]: v for v in subscriber.json_lines() if v.get("job_id") == job_id}
    finally:
        subscriber.stop()
        assert daemon.stop() == 0
    out = tmp_path / "out" / job_id
    for number, part in ((1, "narrowing"), (2, "widening")):
        body = messages[f"verification/{number}"]["body"]
        assert body["finger_set"] == number and body["file"] == f"set-{number}/verification.json"
        assert [s["part"] for s in body["scenarios"]] == [part]
        folder = out / f"set-{number}"
        written = json.loads((folder / "verification.json").read_text())
        assert written["scenarios"][0]["fcso"]["success_rate"] == body["scenarios"][0]["success_rate"]
        assert "<!-- fcso verify -->" in (folder / "report.html").read_text()
        assert any(
            b["key_expr"].endswith(f"/verification/{number}")
            for b in read_record(folder / VERIFICATION_RECORD_NAME).of(TOPIC_BUS)
        )
    assert "verification" not in messages
