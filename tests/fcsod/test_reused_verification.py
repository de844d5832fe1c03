"""A job the finger library serves has its reused finger verified on its own parts, after it is done and again after a
crash cut that off (issue 44, item 1: its worker died of ``run.sets`` being None)."""

from __future__ import annotations

import json
import shutil

from fcsod.bus.messages import VerificationMessage
from fcsod.config import load_daemon_config
from fcsod.job.events import JobFinished, VerificationFinished
from fcsod.job.running import run_job
from fcsod.job.task import JobTask, VerificationTask
from fcsod.job.verification import verify_again
from tests.fcsod_helpers import DATA, drop_job, free_port, write_config

QUEUED = "2026-01-01T00:00:00Z"


def _verified(events: list) -> tuple[str, str | None, list[VerificationMessage]]:
    (verified,) = [e for e in events if isinstance(e, VerificationFinished)]
    messages = [VerificationMessage.model_validate_json(m.payload) for m in verified.messages]
    return verified.state, verified.error, messages


def test_a_reused_finger_is_verified_on_the_new_jobs_part_after_done_and_again_after_a_crash(tmp_path):
    config = load_daemon_config(
        write_config(tmp_path, free_port(), reuse=True, verify="enabled = true\ntop_k = 0\ntrials = 1")
    )
    # the daemon makes its state folder (journal, finger library) before any job runs
    (tmp_path / "state").mkdir()
    watch = tmp_path / "watch"
    drop_job(watch / "a", {"cube.stl": DATA / "20mm-xyz-cube.stl"})
    # the same parts in a folder of another name (a copied job folder)
    shutil.copytree(watch / "a", watch / "a-copy")
    delivered = []
    run_job(JobTask("a", str(watch / "a"), 1, QUEUED, QUEUED, config), delivered.append)
    assert _verified(delivered)[:2] == ("done", None)

    events = []
    run_job(JobTask("a-copy", str(watch / "a-copy"), 1, QUEUED, QUEUED, config), events.append)
    (finished,) = [e for e in events if isinstance(e, JobFinished)]
    assert finished.state == "done" and finished.verify_limit_seconds is not None, "no verification announced"
    out = tmp_path / "out" / "a-copy"
    assert json.loads((out / "report.json").read_text())["reused"][0]["delivered_by_job"] == "a"
    state, error, (message,) = _verified(events)
    assert (state, error) == ("done", None)
    # this job's part, with the grasps the library delivered for it, on the reused finger
    plan = json.loads(next(m.payload for m in finished.messages if m.topic == "plan"))
    delivered_grasps = plan["sets"][0]["parts"][0]["grasps"]
    assert message.job_id == "a-copy" and message.file == "verification.json"
    assert {(s.part, s.pose_index) for s in message.scenarios} == {
        (g["part"], g["pose_index"]) for g in delivered_grasps
    }
    assert all(s.trials_run == 1 for s in message.scenarios)
    written = json.loads((out / "verification.json").read_text())
    assert written["passed"] == message.passed

    # a crash cut the verification off: the next start runs it again from the output folder, the same way
    for name in ("verification.json", "verification.mcap", "verification.html"):
        (out / name).unlink()
    again = []
    verify_again(VerificationTask("a-copy", str(watch / "a-copy"), config), again.append)
    state, error, (rerun,) = _verified(again)
    assert (state, error) == ("done", None)
    assert [(s.part, s.pose_index, s.success_rate) for s in rerun.scenarios] == [
        (s.part, s.pose_index, s.success_rate) for s in message.scenarios
    ]
    assert (out / "verification.json").is_file()
