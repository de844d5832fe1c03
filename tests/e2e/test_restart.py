"""Crash and stop behaviour: SIGKILL during a job, systemd notifications, SIGTERM, the per-job time limit."""

from __future__ import annotations

import os
import signal
import socket
import sqlite3
import threading
import time

from fcsod.record.recorder import TOPIC_STATE, read_record
from tests.conftest import HANG_GUARD_S, process_running
from tests.fcsod_helpers import (
    DATA,
    SLOW_DESIGN,
    drop_job,
    free_port,
    slow_manifest,
    start_daemon,
    start_subscriber,
    write_config,
)

SOLAR = DATA / "solar_tracker.stl"


class FakeSystemd:
    """A notify socket read by a thread, as systemd reads it."""

    def __init__(self, path):
        self.path = str(path)
        self.received: list[str] = []
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self._sock.bind(self.path)
        self._sock.settimeout(0.2)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        while not self._stop.is_set():
            try:
                self.received.append(self._sock.recv(4096).decode())
            except TimeoutError:
                continue

    def wait_for(self, message: str, timeout: float = HANG_GUARD_S) -> int:
        """Index of the first ``message`` received; AssertionError after ``timeout`` s."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if message in self.received:
                return self.received.index(message)
            time.sleep(0.05)
        raise AssertionError(f"{message} not received; got {self.received[-10:]}")

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        self._sock.close()


def test_sigkill_during_a_job_then_restart_runs_it_exactly_once(tmp_path):
    port = free_port()
    # the first daemon's settings make the job run for minutes, so it is surely running when
    # the daemon is killed; the restarted daemon's quick settings let it finish
    config = write_config(tmp_path, port, design=SLOW_DESIGN)
    systemd = FakeSystemd(tmp_path / "notify.sock")
    environment = {"NOTIFY_SOCKET": systemd.path, "WATCHDOG_USEC": "1000000"}

    first = start_daemon(config, env=environment)
    try:
        systemd.wait_for("READY=1")
        drop_job(tmp_path / "watch" / "solar", {"solar_tracker.stl": SOLAR})
        started = first.wait_for(lambda v: isinstance(v, dict) and v.get("message") == "job started")
        first.wait_for(lambda v: isinstance(v, dict) and v.get("stage") == "load")
    finally:
        first.stop(signal.SIGKILL)
    job_id, worker = started["job_id"], started["worker_pid"]
    deadline = time.monotonic() + HANG_GUARD_S
    while process_running(worker) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not process_running(worker), "the worker outlived the killed daemon"
    journal = tmp_path / "state" / "journal.sqlite3"
    with sqlite3.connect(journal) as db:
        assert db.execute("SELECT state FROM jobs WHERE job_id = ?", (job_id,)).fetchone() == ("running",)
    assert not (tmp_path / "out" / job_id).exists()

    systemd.received.clear()
    config = write_config(tmp_path, port)
    second = start_daemon(config, env=environment)
    # the restarted daemon may finish the job before any subscriber connects: this one also asks for what was
    # published before it came (the journal's answer), so it does not depend on which is quicker
    subscriber = start_subscriber(config)
    try:
        done = subscriber.wait_for(
            lambda v: isinstance(v, dict) and v.get("topic") == "status" and v["body"]["state"] in ("done", "failed")
        )
        assert done["job_id"] == job_id and done["body"]["state"] == "done", done
        assert done["body"]["attempt"] == 2
        assert systemd.wait_for("WATCHDOG=1") > systemd.wait_for("READY=1")
    finally:
        subscriber.stop()
        assert second.stop(signal.SIGTERM) == 0
    systemd.wait_for("STOPPING=1")
    systemd.close()

    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [job_id], "partial output left behind"
    with sqlite3.connect(journal) as db:
        assert db.execute("SELECT state, attempt FROM jobs").fetchall() == [("done", 2)]
    assert sum(1 for v in second.json_lines() if v.get("message") == "job started") == 1
    assert any(v.get("message") == "re-queued job left running by the previous run" for v in second.json_lines())
    # published once: at most one done status came live, and any answer from the journal is that one
    statuses = [v for v in subscriber.json_lines() if v.get("topic") == "status" and v["body"]["state"] == "done"]
    assert sum(v["source"] == "live" for v in statuses) <= 1
    assert all(v["body"] == done["body"] for v in statuses)
    record = read_record(tmp_path / "out" / job_id / "job.mcap")
    assert [s["state"] for s in record.of(TOPIC_STATE)] == ["queued", "running", "done"]


def test_job_over_its_time_limit_fails_with_a_finished_record(tmp_path):
    config = write_config(tmp_path, free_port(), extra="[jobs]\ntime_limit_seconds = 1.0\nstop_grace_seconds = 3.0\n")
    daemon = start_daemon(config)
    subscriber = start_subscriber(config, extra=["--no-query"])
    try:
        # a design of many minutes: over the 1 s limit on any machine
        drop_job(
            tmp_path / "watch" / "slow", {"job.toml": slow_manifest("solar_tracker.stl"), "solar_tracker.stl": SOLAR}
        )
        failed = subscriber.wait_for(
            lambda v: isinstance(v, dict) and v.get("topic") == "status" and v["body"]["state"] in ("done", "failed")
        )
    finally:
        subscriber.stop()
        assert daemon.stop() == 0
    assert failed["body"]["state"] == "failed"
    assert "time limit exceeded" in failed["body"]["error"] and "jobs.time_limit_seconds" in failed["body"]["error"]
    out = tmp_path / "out" / failed["job_id"]
    assert sorted(p.name for p in out.iterdir()) == ["job.mcap"]
    record = read_record(out / "job.mcap")
    assert not record.truncated
    assert record.of(TOPIC_STATE)[-1]["state"] == "failed"


def test_worker_killed_mid_job_fails_that_job_only(tmp_path):
    """A worker dying (as under the OOM killer) fails its job with a salvaged, finished record; the next job runs."""
    config = write_config(tmp_path, free_port())
    daemon = start_daemon(config)
    subscriber = start_subscriber(config, extra=["--no-query"])
    try:
        # a design of many minutes: still running when its worker is killed
        drop_job(
            tmp_path / "watch" / "victim", {"job.toml": slow_manifest("solar_tracker.stl"), "solar_tracker.stl": SOLAR}
        )
        started = daemon.wait_for(lambda v: isinstance(v, dict) and v.get("message") == "job started")
        # the design's first progress line (it has done and total): the record was flushed after the job's load
        # step before it. The load step's own "step load finished" line (stage "load") is sent before that flush:
        # killed on it, the worker raced its own record
        daemon.wait_for(lambda v: isinstance(v, dict) and v.get("done") is not None)
        os.kill(started["worker_pid"], signal.SIGKILL)
        failed = subscriber.wait_for(
            lambda v: isinstance(v, dict) and v.get("topic") == "status" and v["body"]["state"] == "failed", 60
        )
        drop_job(tmp_path / "watch" / "next", {"cube.stl": DATA / "20mm-xyz-cube.stl"})
        done = subscriber.wait_for(
            lambda v: isinstance(v, dict) and v.get("topic") == "status" and v["body"]["state"] == "done", 90
        )
    finally:
        subscriber.stop()
        assert daemon.stop() == 0
    assert failed["job_id"] == started["job_id"] and done["job_id"] != started["job_id"]
    assert "worker process died while running the job (killed by signal SIGKILL)" in failed["body"]["error"]
    out = tmp_path / "out" / failed["job_id"]
    assert sorted(p.name for p in out.iterdir()) == ["job.mcap"]
    record = read_record(out / "job.mcap")
    assert not record.truncated
    # what the worker recorded before it died is kept, then the failure
    assert [s["state"] for s in record.of(TOPIC_STATE)] == ["queued", "running", "failed"]
    assert any(line["message"].startswith("loaded solar_tracker.stl") for line in record.of("/job/log"))
