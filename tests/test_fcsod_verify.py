"""fcsod with [verify]: the design is done and published first, its verification follows on zenoh, in the journal and in MCAP."""

from __future__ import annotations

import json

from examples.sim_parts import ridged_block
from fcsod.recorder import TOPIC_BUS, read_record
from fcsod.verification import RECORD_NAME, TOPIC_VERIFICATION, TOPIC_VERIFICATION_SCENE

from tests.fcsod_helpers import drop_job, finished, free_port, start_daemon, start_subscriber, write_config

MANIFEST = '[[parts]]\nfile = "ridged.stl"\n\n[sampler]\nyaw_deg = [0]\n'


def test_done_job_is_verified_published_recorded_and_answered(tmp_path):
    port = free_port()
    config = write_config(tmp_path, port, extra="[verify]\nenabled = true\ntrials = 2\n")
    part = tmp_path / "ridged.stl"
    ridged_block().export(part)
    daemon = start_daemon(config)
    subscriber = start_subscriber(config)
    try:
        drop_job(tmp_path / "watch" / "ridged", {"job.toml": MANIFEST, "ridged.stl": part})
        done = finished(subscriber, "ridged")
        assert done["body"]["state"] == "done", done
        job_id = done["job_id"]
        message = subscriber.wait_for(lambda v: isinstance(v, dict) and v.get("topic") == "verification" and v["job_id"] == job_id, 120)
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
        record = read_record(out / RECORD_NAME)
        assert record.of(TOPIC_VERIFICATION)[0]["passed"] == body["passed"]
        scenes = record.of(TOPIC_VERIFICATION_SCENE)
        assert len(scenes) > 10 and scenes[0]["entities"][0]["triangles"]
        assert any(b["key_expr"].endswith("/verification") for b in record.of(TOPIC_BUS))

        # a late joiner gets it from the journal's queryable
        late = start_subscriber(config)
        try:
            answered = late.wait_for(lambda v: isinstance(v, dict) and v.get("topic") == "verification" and v["job_id"] == job_id, 30)
            assert answered["source"] != "live" and answered["body"] == body
        finally:
            late.stop()
    finally:
        subscriber.stop()
        assert daemon.stop() == 0
