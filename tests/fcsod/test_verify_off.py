"""``[verify] enabled = false`` turns verification off in the daemon's job worker: no choice among top_k candidates by
simulation, no verification after done, no verification file or message (issue 44, item 5)."""

from __future__ import annotations

import json

from fcsod.config import load_daemon_config
from fcsod.job.events import JobFinished, Log, VerificationFinished, VerificationStarted
from fcsod.job.running import run_job
from fcsod.job.task import JobTask
from tests.fcsod_helpers import DATA, drop_job, free_port, write_config


def test_verification_off_with_the_default_top_k_verifies_nothing(tmp_path):
    # top_k keeps its default of 3: enabled = false alone must turn the choice by simulation off too
    config = load_daemon_config(write_config(tmp_path, free_port(), verify="enabled = false"))
    assert config.verify.top_k == 3 and not config.verify.enabled
    folder = tmp_path / "watch" / "cube"
    drop_job(folder, {"cube.stl": DATA / "20mm-xyz-cube.stl"})
    events = []
    run_job(JobTask("cube", str(folder), 1, "2026-01-01T00:00:00Z", "2026-01-01T00:00:00Z", config), events.append)
    (finished,) = [e for e in events if isinstance(e, JobFinished)]
    assert (finished.state, finished.error) == ("done", None)
    assert finished.verify_limit_seconds is None, "a verification after done was announced"
    assert not [e for e in events if isinstance(e, (VerificationStarted, VerificationFinished))]
    assert [m.topic for m in finished.messages if m.topic.startswith("verification")] == []
    out = tmp_path / "out" / "cube"
    assert not list(out.glob("verification*"))
    assert json.loads((out / "report.json").read_text()).get("verification") is None
    # nothing simulated: no line of a verification's progress or verdict (the step's name is logged all the same)
    logged = [e.message for e in events if isinstance(e, Log)]
    assert not [line for line in logged if line.startswith("verification") or "delivered" in line]
