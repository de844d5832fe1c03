"""Finger reuse through the real daemon (METHOD §11b): a repeated job mounts the delivered finger, after kill -9 too."""

from __future__ import annotations

import hashlib
import json
import re
import signal
import zipfile

from fcsod.cli import main
from fcsod.record.recorder import TOPIC_BUS, read_record
from tests.fcsod_helpers import DATA, drop_job, finished, free_port, start_daemon, start_subscriber, write_config

CUBE = DATA / "20mm-xyz-cube.stl"
#: Other parts: the same file scaled, another geometry
SMALLER_CUBE = '[[parts]]\nfile = "cube.stl"\nscale_to_mm = 18\n'


def _plan(subscriber, job_id: str) -> dict:
    return subscriber.wait_for(
        lambda v: isinstance(v, dict) and v.get("job_id") == job_id and v.get("topic") == "plan", 30
    )["body"]


def test_a_repeated_job_reuses_the_delivered_finger_after_kill_9_and_other_parts_do_not(tmp_path, capsys):
    config = write_config(tmp_path, free_port(), reuse=True)
    daemon = start_daemon(config)
    subscriber = start_subscriber(config)
    try:
        drop_job(tmp_path / "watch" / "job-a", {"cube.stl": CUBE})
        first = finished(subscriber, "job-a")
        assert first["body"]["state"] == "done", first["body"]["error"]
        plan_a = _plan(subscriber, first["job_id"])
    finally:
        subscriber.stop()
        # the library must hold what job A delivered without a clean stop
        daemon.stop(signal.SIGKILL)
    out_a = tmp_path / "out" / first["job_id"]
    finger_sha256 = hashlib.sha256((out_a / "finger.stl").read_bytes()).hexdigest()
    assert plan_a["sets"][0]["finger_id"] is None and plan_a["sets"][0]["finger_sha256"] == finger_sha256

    daemon = start_daemon(config)
    subscriber = start_subscriber(config)
    try:
        drop_job(tmp_path / "watch" / "job-a-again", {"cube.stl": CUBE})
        again = finished(subscriber, "job-a-again")
        assert again["body"]["state"] == "done", again["body"]["error"]
        drop_job(tmp_path / "watch" / "job-b", {"cube.stl": CUBE, "job.toml": SMALLER_CUBE})
        other = finished(subscriber, "job-b")
        assert other["body"]["state"] == "done", other["body"]["error"]
        plan_again, plan_b = _plan(subscriber, again["job_id"]), _plan(subscriber, other["job_id"])
    finally:
        subscriber.stop()
        assert daemon.stop() == 0

    # A': the finger A delivered, named by its library id and sha256; nothing designed, no finger copy printed
    out_again = tmp_path / "out" / again["job_id"]
    assert sorted(p.name for p in out_again.iterdir()) == ["build.3mf", "job.mcap", "report.json"]
    (reused,) = plan_again["sets"]
    assert (reused["finger_id"], reused["finger_sha256"], reused["reused_from_job"]) == (
        1,
        finger_sha256,
        first["job_id"],
    )
    assert reused["finger_copies"] == 0 and reused["finger_file"] == f"../{first['job_id']}/finger.stl"
    assert [p["part"] for p in reused["parts"]] == ["cube"]
    # the same part in the same file frame: the delivered grasps unchanged
    assert reused["parts"][0]["grasps"] == plan_a["sets"][0]["parts"][0]["grasps"]
    with zipfile.ZipFile(out_again / "build.3mf") as archive:
        model = archive.read("3D/3dmodel.model").decode()
    assert "fcso-finger" not in model and len(re.findall(r"<item ", model)) == 1
    report = json.loads((out_again / "report.json").read_text())
    assert report["reused"][0]["finger_id"] == 1 and report["reused"][0]["jobs_served"] == 2
    assert "no finger designed" in report["message"]
    published = [json.loads(b["payload_text"]) for b in read_record(out_again / "job.mcap").of(TOPIC_BUS)]
    recorded_plan = next(body for body in published if "sets" in body)
    assert recorded_plan["sets"][0]["finger_id"] == 1 and recorded_plan["sets"][0]["finger_sha256"] == finger_sha256
    capsys.readouterr()
    assert main(["audit", str(out_again / "job.mcap"), "--verify", str(out_again)]) == 0
    told = capsys.readouterr().out
    assert f"set 1: mount library finger 1 delivered by {first['job_id']}, ../{first['job_id']}/finger.stl" in told
    assert "verification passed" in told

    # B: other parts, a new finger designed and printed
    out_b = tmp_path / "out" / other["job_id"]
    assert (out_b / "finger.stl").is_file() and plan_b["sets"][0]["finger_id"] is None
    # the daemon repairs by default: a closed file goes through unchanged
    part_a = json.loads((out_a / "report.json").read_text())["parts"][0]
    assert part_a["repair"]["volume_change_percent"] == 0.0 and part_a["repairs"] == []

    # the library: A's finger served two jobs, B's one; a retired finger is listed as such
    capsys.readouterr()
    assert main(["fingers", "list", "--config", str(config)]) == 0
    listed = capsys.readouterr().out.splitlines()
    assert listed[0].startswith("1: active, 2/100 jobs, sha256 " + finger_sha256) and listed[0].endswith("parts cube")
    assert listed[1].startswith("2: active, 1/100 jobs") and listed[1].endswith("parts cube")
    assert main(["fingers", "retire", "1", "--config", str(config)]) == 0
    assert main(["fingers", "retire", "1", "--config", str(config)]) == 2
    assert main(["fingers", "list", "--config", str(config)]) == 0
    assert capsys.readouterr().out.splitlines()[1].startswith("1: retired ")
