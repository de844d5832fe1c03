"""The daemon's bad-input corpus (tests/bad_jobs.py): each bad job folder is refused by the daemon's job worker with a
message naming its file and the defect, whether the daemon repairs parts or not; a mesh file's refusal is the one
``fcso design`` gives without ``--repair``. Bad input is refused before any repair: a repair never turns it into a
design or an internal error.
"""

from __future__ import annotations

import subprocess
import sys

import pytest

from fcsod.config import load_daemon_config
from fcsod.job.events import JobFinished, Log
from fcsod.job.running import run_job
from fcsod.job.task import JobTask
from fcsod.record.recorder import JOB_RECORD_NAME
from tests.bad_jobs import BAD_JOBS, BadJob, write_bad_job
from tests.conftest import HANG_GUARD_S, REPO
from tests.fcsod_helpers import free_port, write_config


def _cases():
    for job in BAD_JOBS:
        for repair in (True, False):
            yield pytest.param(job, repair, id=f"{job.name}-repair-{'on' if repair else 'off'}")


def _refusal(tmp_path, job: BadJob, repair: bool) -> str:
    """The error of the daemon's job worker for ``job``, with ``[parts] repair`` as given."""
    config = load_daemon_config(write_config(tmp_path, free_port(), extra=f"[parts]\nrepair = {str(repair).lower()}"))
    folder = tmp_path / "watch" / job.name
    write_bad_job(folder, job)
    events = []
    run_job(JobTask(job.name, str(folder), 1, "2026-01-01T00:00:00Z", "2026-01-01T00:00:00Z", config), events.append)
    (finished,) = [e for e in events if isinstance(e, JobFinished)]
    assert finished.state == "failed", f"{job.name}: not refused ({finished.state})"
    logged = [e.message for e in events if isinstance(e, Log)]
    assert not any("Traceback" in line for line in logged), logged
    # a failed job's output folder holds its record alone
    assert sorted(p.name for p in (tmp_path / "out" / job.name).iterdir()) == [JOB_RECORD_NAME]
    return finished.error


@pytest.mark.parametrize(("job", "repair"), list(_cases()))
def test_the_daemon_refuses_each_bad_job_naming_its_file_and_defect(tmp_path, job, repair):
    error = _refusal(tmp_path, job, repair)
    assert job.file in error and "internal error" not in error, error
    for word in job.words:
        assert word in error, error


@pytest.mark.parametrize("job", [j for j in BAD_JOBS if j.mesh], ids=lambda j: j.name)
def test_the_cli_without_repair_refuses_each_bad_mesh_file_with_the_daemons_words(tmp_path, job):
    folder = tmp_path / job.name
    write_bad_job(folder, job)
    run = subprocess.run(
        [sys.executable, "-m", "fcso.cli", "design", str(folder / job.file), "--out", str(tmp_path / "out")],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=HANG_GUARD_S,
    )
    assert run.returncode == 2 and "Traceback" not in run.stderr, run.stderr
    # the refusal is the last line (trimesh warns of the NaN it casts while it reads the file, before fcso's check)
    line = run.stderr.strip().splitlines()[-1]
    assert line.startswith("fcso: error: ") and job.file in line and all(word in line for word in job.words), line
    assert not (tmp_path / "out").exists()
