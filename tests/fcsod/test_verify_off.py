"""``[verify] enabled = false`` turns verification off in the daemon's job worker: no choice among top_k candidates by
simulation, no verification after done, no verification file or message (issue 44, item 5)."""

from __future__ import annotations

import json

from fcsod.config import load_daemon_config
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
    (finished,) = [e for e in events if e[0] == "finished"]
    state, error, published, verify_limit_s = finished[1:]
    assert (state, error) == ("done", None)
    assert verify_limit_s is None, "a verification after done was announced"
    assert not [e for e in events if e[0] in ("verifying", "verified")]
    assert [m.topic for m in published if m.topic.startswith("verification")] == []
    out = tmp_path / "out" / "cube"
    assert not list(out.glob("verification*"))
    assert json.loads((out / "report.json").read_text()).get("verification") is None
    # nothing simulated: no line of a verification's progress or verdict (the step's name is logged all the same)
    assert not [e for e in events if e[0] == "log" and (e[2].startswith("verification") or "delivered" in e[2])]
