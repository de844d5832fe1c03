"""Faults that lose nothing: a full output disk, the zenoh peer down at start-up, a corrupt journal, a job folder
deleted mid-job.

Each test runs the real daemon (``fcsod run``) and clients as separate
processes; the full disk is a real, small tmpfs mounted over the output root.
"""

from __future__ import annotations

import json
import os
import shutil
import sqlite3
import subprocess
import sys
import uuid
from pathlib import Path

import pytest

from fcsod.bus.pki import add_client, init_pki
from fcsod.record.recorder import TOPIC_STATE, read_record
from fcsod.service.journal import journal_problem
from tests.broken_meshes import sheet_stl
from tests.conftest import HANG_GUARD_S
from tests.fcsod_helpers import (
    DATA,
    REPO,
    Process,
    drop_job,
    finished,
    free_port,
    slow_manifest,
    start_daemon,
    start_subscriber,
    write_config,
)

CUBE = DATA / "20mm-xyz-cube.stl"
SOLAR = DATA / "solar_tracker.stl"
TOPICS = {"status", "quality", "grasps", "design", "plan", "placement"}


def _daemon_says(daemon: Process, message: str, timeout: float = HANG_GUARD_S, **fields) -> dict:
    return daemon.wait_for(
        lambda v: (
            isinstance(v, dict)
            and v.get("message", "").startswith(message)
            and all(v.get(k) == x for k, x in fields.items())
        ),
        timeout,
    )


# ---------------------------------------------------------------- full disk


def _mount_tmpfs(path: Path, size_bytes: int) -> None:
    path.mkdir(parents=True, exist_ok=True)
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size_bytes}", "tmpfs", str(path)], capture_output=True, text=True
    )
    # CI and the development machines run as root; a full disk is only real on a small filesystem
    assert done.returncode == 0, f"cannot mount a small tmpfs at {path} (needs root): {done.stderr.strip()}"


def _fill(path: Path, leave_bytes: int) -> Path:
    """Fill the filesystem of ``path`` with one file until ``leave_bytes`` stay free."""
    filler = path / "filler"
    free = os.statvfs(path).f_bavail * os.statvfs(path).f_frsize
    with open(filler, "wb") as stream:
        stream.write(b"\0" * (free - leave_bytes))
    return filler


def _every_topic_answered(job_id: str):
    """A ``wait_for`` predicate true once the queryable answered every topic of ``job_id``.

    The replies come one by one: waiting for the first one (design) and stopping there lost those after it (plan,
    placement, grasps).
    """
    answered = set()

    def every_topic(v) -> bool:
        if isinstance(v, dict) and v.get("source") == "query" and v.get("job_id") == job_id:
            answered.add(v["topic"])
        return TOPICS <= answered

    return every_topic


@pytest.mark.parametrize(
    "free_bytes", [96 * 1024, 0], ids=["full-while-writing-outputs", "full-before-the-record-starts"]
)
def test_disk_full_while_writing_outputs_fails_the_job_cleanly_and_the_next_job_runs(tmp_path, free_bytes):
    out = tmp_path / "out"
    _mount_tmpfs(out, 8 * 1024 * 1024)
    try:
        config = write_config(tmp_path, free_port())
        daemon = start_daemon(config)
        subscriber = start_subscriber(config, extra=["--no-query"])
        try:
            # 96 kB: room for the record's first stages, not for the outputs
            filler = _fill(out, free_bytes)
            drop_job(tmp_path / "watch" / "full", {"cube.stl": CUBE})
            failed = finished(subscriber, "full")
            filler.unlink()
            drop_job(tmp_path / "watch" / "after", {"cube.stl": CUBE})
            done = finished(subscriber, "after")
        finally:
            subscriber.stop()
            code = daemon.stop()
        assert code == 0
        body = failed["body"]
        assert body["state"] == "failed"
        assert str(out) in body["error"] and "no space left on device" in body["error"], body["error"]
        assert done["body"]["state"] == "done"
        assert not list(out.glob(".tmp-*")), "partial output left behind"
        failed_dir = out / failed["job_id"]
        left = sorted(p.name for p in failed_dir.iterdir()) if failed_dir.exists() else []
        assert left in ([], ["job.mcap"]), left
        if left:
            record = read_record(failed_dir / "job.mcap")
            assert record.of(TOPIC_STATE)[-1]["state"] == "failed"
        assert {"finger.stl", "report.json", "job.mcap"} <= {p.name for p in (out / done["job_id"]).iterdir()}
        with sqlite3.connect(tmp_path / "state" / "journal.sqlite3") as db:
            states = dict(db.execute("SELECT job_id, state FROM jobs").fetchall())
        assert states == {failed["job_id"]: "failed", done["job_id"]: "done"}
    finally:
        subprocess.run(["umount", str(out)], check=False)


# ---------------------------------------------------------------- zenoh peer down at start-up


def test_zenoh_router_down_at_start_then_up_late_subscriber_gets_every_result(tmp_path):
    """The daemon connects over mTLS to a plant router that is down at start-up; a controller behind the router comes
    later.
    """
    port, router_port = free_port(), free_port()
    pki = tmp_path / "pki"
    files = init_pki(pki, "test", ["ctl1", "router"], hosts=["127.0.0.1"], port=port)
    # the router is reached at an address: its certificate must name it
    router_dir = add_client(pki, "router", [], hosts=["127.0.0.1"])
    config = write_config(
        tmp_path,
        port,
        scheme="tls",
        bus_extra=f'signing_key = "{files.signing_key}"',
        zenoh_extra=f'config_file = "{files.daemon_zenoh_config}"\nconnect = ["tls/127.0.0.1:{router_port}"]',
    )
    daemon = start_daemon(config)
    router = None
    try:
        drop_job(tmp_path / "watch" / "offline", {"cube.stl": CUBE})
        done = _daemon_says(daemon, "job done")
        tls = {name: str(router_dir / f"{name}.pem") for name in ("ca", "cert", "key")}
        router_config = tmp_path / "router.json5"
        router_config.write_text(
            json.dumps(
                {
                    "mode": "router",
                    "listen": {"endpoints": [f"tls/127.0.0.1:{router_port}"]},
                    "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
                    "transport": {
                        "link": {
                            "tls": {
                                "root_ca_certificate": tls["ca"],
                                "listen_certificate": tls["cert"],
                                "listen_private_key": tls["key"],
                                "connect_certificate": tls["cert"],
                                "connect_private_key": tls["key"],
                                "enable_mtls": True,
                            }
                        }
                    },
                }
            )
        )
        router = subprocess.Popen(
            [sys.executable, "-m", "tests.zenoh_probe", "--config", str(router_config), "--hold"],
            cwd=REPO,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert json.loads(router.stdout.readline())["event"] == "open"
        # the cell controller reaches the daemon only through the router
        controller = pki / "clients" / "ctl1"
        late = start_subscriber(
            config,
            extra=[
                "--zenoh-config",
                str(controller / "zenoh.json5"),
                "--verify-key",
                str(controller / "signing.pub"),
                "--connect",
                f"tls/127.0.0.1:{router_port}",
            ],
        )
        try:
            late.wait_for(_every_topic_answered(done["job_id"]))
        finally:
            late.stop()
    finally:
        if router is not None:
            router.kill()
            router.wait()
        assert daemon.stop() == 0
    got = {v["topic"]: v for v in late.json_lines() if v.get("source") == "query" and v.get("job_id") == done["job_id"]}
    assert set(got) == TOPICS
    assert got["status"]["body"]["state"] == "done" and all(v["signature_ok"] for v in got.values())
    assert got["design"]["sha256_ok"] is True


# ---------------------------------------------------------------- corrupt journal


def _fcsod(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "fcsod", *args], cwd=REPO, capture_output=True, text=True, timeout=HANG_GUARD_S
    )


def test_corrupt_journal_stops_the_start_and_rebuild_restores_it_without_rerunning_jobs(tmp_path):
    config = write_config(tmp_path, free_port())
    daemon = start_daemon(config)
    subscriber = start_subscriber(config, extra=["--no-query"])
    try:
        drop_job(tmp_path / "watch" / "cube", {"cube.stl": CUBE})
        drop_job(tmp_path / "watch" / "broken", {"top_face.stl": sheet_stl(DATA / "20mm-xyz-cube.stl")})
        done, failed = finished(subscriber, "cube"), finished(subscriber, "broken")
    finally:
        subscriber.stop()
        assert daemon.stop() == 0
    journal = tmp_path / "state" / "journal.sqlite3"
    with sqlite3.connect(journal) as db:
        before = db.execute(
            "SELECT job_id, folder, state, attempt, queued_at, started_at, finished_at, error FROM jobs ORDER BY job_id"
        ).fetchall()
    assert _fcsod("journal", "check", "--config", str(config)).returncode == 0
    with open(journal, "r+b") as stream:
        stream.write(b"this is not an SQLite header" * 4)

    refused = _fcsod("run", "--config", str(config))
    assert refused.returncode == 2
    assert f"{journal}: the journal is corrupt" in refused.stderr and "fcsod journal rebuild" in refused.stderr
    assert "Traceback" not in refused.stderr + refused.stdout
    check = _fcsod("journal", "check", "--config", str(config))
    assert check.returncode == 1 and "corrupt" in check.stdout

    rebuild = _fcsod("journal", "rebuild", "--config", str(config))
    assert rebuild.returncode == 0, rebuild.stderr
    assert "from 2 job records: 1 done, 1 failed" in rebuild.stdout
    assert list(journal.parent.glob("journal.sqlite3.corrupt-*")), "the corrupt journal must be kept"
    assert _fcsod("journal", "check", "--config", str(config)).returncode == 0
    with sqlite3.connect(journal) as db:
        after = db.execute(
            "SELECT job_id, folder, state, attempt, queued_at, started_at, finished_at, error FROM jobs ORDER BY job_id"
        ).fetchall()
    assert after == before

    daemon = start_daemon(config)
    late = start_subscriber(config)
    try:
        _daemon_says(daemon, "job already known: not run again", 30, job_id=done["job_id"])
        _daemon_says(daemon, "job already known: not run again", 30, job_id=failed["job_id"])
        late.wait_for(_every_topic_answered(done["job_id"]))
    finally:
        late.stop()
        assert daemon.stop() == 0
    assert not [v for v in daemon.json_lines() if v.get("message") == "job started"], "a finished job ran again"
    got = {v["topic"] for v in late.json_lines() if v.get("source") == "query" and v.get("job_id") == done["job_id"]}
    assert got == TOPICS


def test_journal_check_finds_a_damaged_page(tmp_path):
    journal = tmp_path / "journal.sqlite3"
    with sqlite3.connect(journal) as db:
        db.execute(
            "CREATE TABLE jobs (job_id TEXT PRIMARY KEY, folder TEXT, state TEXT, attempt INTEGER, queued_at TEXT, "
            "started_at TEXT, finished_at TEXT, error TEXT)"
        )
        db.execute("CREATE TABLE messages (job_id TEXT, payload BLOB)")
        db.execute("CREATE INDEX by_folder ON jobs (folder)")
        db.executemany(
            "INSERT INTO jobs VALUES (?, ?, 'done', 1, '', '', '', NULL)",
            [(uuid.uuid4().hex, "x" * 200) for _ in range(400)],
        )
    assert journal_problem(journal) is None
    with open(journal, "r+b") as stream:
        stream.seek(5 * 4096)
        stream.write(os.urandom(4096))
    assert journal_problem(journal) is not None
    assert journal_problem(tmp_path / "absent.sqlite3") is None


# ---------------------------------------------------------------- job folder deleted mid-job


def test_job_folder_deleted_while_its_job_runs_fails_cleanly(tmp_path):
    config = write_config(tmp_path, free_port())
    daemon = start_daemon(config)
    subscriber = start_subscriber(config, extra=["--no-query"])
    try:
        folder, waiting = tmp_path / "watch" / "withdrawn", tmp_path / "watch" / "withdrawn-while-queued"
        # a design of many minutes: still running when its folder is deleted, which withdraws it at once
        drop_job(folder, {"job.toml": slow_manifest("solar_tracker.stl"), "solar_tracker.stl": SOLAR})
        _daemon_says(daemon, "job started")
        daemon.wait_for(lambda v: isinstance(v, dict) and v.get("stage") == "load")
        # one job at a time: this one waits in the queue while the first runs
        drop_job(waiting, {"cube.stl": CUBE})
        _daemon_says(daemon, "job queued", folder=str(waiting))
        shutil.rmtree(waiting)
        shutil.rmtree(folder)
        failed = finished(subscriber, "withdrawn")
        failed_queued = finished(subscriber, "withdrawn-while-queued")
        drop_job(tmp_path / "watch" / "next", {"cube.stl": CUBE})
        done = finished(subscriber, "next")
    finally:
        subscriber.stop()
        code = daemon.stop()
    assert code == 0
    assert failed["body"]["state"] == "failed"
    assert (
        failed["body"]["error"]
        == f"{folder}: the job folder was deleted while its job ran: the job is withdrawn, nothing of it is published"
    )
    assert sorted(p.name for p in (tmp_path / "out" / failed["job_id"]).iterdir()) == ["job.mcap"]
    published = {v["topic"] for v in subscriber.json_lines() if v.get("job_id") == failed["job_id"]}
    assert published == {"status"}, "a withdrawn job's design must not reach the cell"
    assert failed_queued["body"]["state"] == "failed"
    assert failed_queued["body"]["error"].startswith(f"{waiting}: the job folder was deleted while its job ran")
    assert done["body"]["state"] == "done"
    assert not list((tmp_path / "out").glob(".tmp-*"))


# ---------------------------------------------------------------- job workers that cannot start


def test_workers_that_cannot_start_fail_the_queued_jobs_with_why_instead_of_starting_again(tmp_path):
    # a broken installation as an upgrade leaves one: a dependency only the job's code loads (MuJoCo) fails to import
    broken = tmp_path / "broken-site" / "mujoco"
    broken.mkdir(parents=True)
    (broken / "__init__.py").write_text('raise ImportError("this mujoco is broken on purpose")\n')
    config = write_config(tmp_path, free_port())
    daemon = start_daemon(config, env={"PYTHONPATH": str(broken.parent)})
    subscriber = start_subscriber(config, extra=["--no-query"])
    try:
        drop_job(tmp_path / "watch" / "first", {"cube.stl": CUBE})
        first = finished(subscriber, "first")
        drop_job(tmp_path / "watch" / "second", {"cube.stl": CUBE})
        second = finished(subscriber, "second")
    finally:
        subscriber.stop()
        code = daemon.stop()
    assert code == 0
    for failed in (first, second):
        assert failed["body"]["state"] == "failed"
        error = failed["body"]["error"]
        assert error.startswith("job workers cannot start (ImportError: this mujoco is broken on purpose)"), error
        assert sorted(p.name for p in (tmp_path / "out" / failed["job_id"]).iterdir()) == ["job.mcap"]
    # no more workers than those started before the first said why (one job at a time, one spare); those may still
    # be exiting when the daemon stops, which then does not log them
    died = [v for v in daemon.json_lines() if v.get("message") == "worker process exited before taking a job"]
    assert len(died) <= 2, died
