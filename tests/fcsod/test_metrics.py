"""The daemon's metrics as Prometheus' own linter reads them (``promtool check metrics``, Debian's prometheus)."""

from __future__ import annotations

import shutil
import subprocess

from prometheus_client import generate_latest

from fcsod.service.journal import Journal
from fcsod.service.metrics import DaemonMetrics
from tests.conftest import HANG_GUARD_S


def test_the_metrics_pass_promtool_and_tell_held_cancelled_and_each_verification(tmp_path):
    promtool = shutil.which("promtool")
    assert promtool, "promtool is not installed: make test installs it (apt-get install prometheus)"
    journal = Journal(tmp_path / "journal.sqlite3")
    journal.add("a", "/watch/a", "t0")
    journal.mark_running("a", "t1")
    journal.mark_finished("a", "held", "t2", "misses the policy")
    journal.close()
    metrics = DaemonMetrics(tmp_path / "journal.sqlite3")
    metrics.jobs_finished.labels("cancelled").inc()
    metrics.job_seconds.labels("done").observe(12.0)
    metrics.last_success.set_to_current_time()
    metrics.verified(False)
    text = generate_latest(metrics.registry)
    run = subprocess.run([promtool, "check", "metrics"], input=text, capture_output=True, timeout=HANG_GUARD_S)
    assert run.returncode == 0, run.stdout.decode() + run.stderr.decode()
    page = text.decode()
    for line in (
        'fcsod_jobs{state="held"} 1.0',
        'fcsod_jobs_finished_total{state="cancelled"} 1.0',
        'fcsod_verifications_total{result="failed"} 1.0',
        'fcsod_job_duration_seconds_count{state="done"} 1.0',
    ):
        assert line in page
    assert "fcsod_build_info{" in page and "process_resident_memory_bytes" in page
    assert "fcsod_last_success_timestamp_seconds" in page
