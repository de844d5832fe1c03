"""Finger reuse through the real daemon (METHOD §11b): a repeated job mounts the delivered finger, after kill -9 too;
a job of a part 1 % smaller keeps min_retained on it and mounts it too; a part 10 % smaller gets its own finger."""

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
#: Other parts: the same file scaled, another geometry. 18 mm: every side 10 % off A's 20 mm, beyond [reuse]
#: similar_size_percent (5 %), so A's finger is not even evaluated for it
SMALLER_CUBE = '[[parts]]\nfile = "cube.stl"\nscale_to_mm = 18\n'
#: Not the same geometry, 1 % smaller: within 5 % of A's cube, so A's finger is evaluated on it
SLIGHTLY_SMALLER_CUBE = '[[parts]]\nfile = "cube.stl"\nscale_to_mm = 19.8\n'


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
        drop_job(tmp_path / "watch" / "job-c", {"cube.stl": CUBE, "job.toml": SLIGHTLY_SMALLER_CUBE})
        near = finished(subscriber, "job-c")
        assert near["body"]["state"] == "done", near["body"]["error"]
        plan_again, plan_b = _plan(subscriber, again["job_id"]), _plan(subscriber, other["job_id"])
        plan_c = _plan(subscriber, near["job_id"])
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
    assert "record check passed" in told

    # B: other parts, a new finger designed and printed
    out_b = tmp_path / "out" / other["job_id"]
    assert (out_b / "finger.stl").is_file() and plan_b["sets"][0]["finger_id"] is None
    # the daemon repairs by default: a closed file goes through unchanged
    part_a = json.loads((out_a / "report.json").read_text())["parts"][0]
    assert part_a["repair"]["volume_change_percent"] == 0.0 and part_a["repairs"] == []

    # C: not the same part, but it keeps min_retained on A's finger: A's finger, its own grasps, nothing printed
    out_c = tmp_path / "out" / near["job_id"]
    assert sorted(p.name for p in out_c.iterdir()) == ["build.3mf", "job.mcap", "report.json"]
    (reused_c,) = plan_c["sets"]
    assert (reused_c["finger_id"], reused_c["finger_sha256"], reused_c["finger_copies"]) == (1, finger_sha256, 0)
    report_c = json.loads((out_c / "report.json").read_text())
    (part_c,) = report_c["reused"][0]["parts"]
    assert part_c["library_part"] is None and part_c["part"] == "cube"
    min_retained = plan_c["min_retained"]
    assert part_c["worst_retained"] >= min_retained and plan_c["min_retained_reached"]
    assert plan_c["worst_retained"] == part_c["worst_retained"] == report_c["reused"][0]["worst_retained"]
    assert f"worst retained {part_c['worst_retained']:.3f}" in report_c["message"]
    # the grasps are the 19.8 mm part's own on the pad, not A's moved: they close on a narrower part
    widths_a = sorted(g["closing_width_mm"] for g in plan_a["sets"][0]["parts"][0]["grasps"])
    widths_c = sorted(g["closing_width_mm"] for g in reused_c["parts"][0]["grasps"])
    assert len(widths_c) == len(widths_a) and all(c < a for c, a in zip(widths_c, widths_a))
    with zipfile.ZipFile(out_c / "build.3mf") as archive:
        assert "fcso-finger" not in archive.read("3D/3dmodel.model").decode()

    # the library: A's finger served three jobs, B's one; a retired finger is listed as such
    capsys.readouterr()
    assert main(["fingers", "list", "--config", str(config)]) == 0
    listed = capsys.readouterr().out.splitlines()
    assert listed[0].startswith("1: active, 3/100 jobs, sha256 " + finger_sha256) and listed[0].endswith("parts cube")
    assert listed[1].startswith("2: active, 1/100 jobs") and listed[1].endswith("parts cube")
    assert main(["fingers", "retire", "1", "--config", str(config)]) == 0
    assert main(["fingers", "retire", "1", "--config", str(config)]) == 2
    assert main(["fingers", "list", "--config", str(config)]) == 0
    assert capsys.readouterr().out.splitlines()[1].startswith("1: retired ")
