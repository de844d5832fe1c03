"""Job folders, readiness, the watcher, the journal, the MCAP recorder and audit, sd_notify: each on real files."""

from __future__ import annotations

import logging
import multiprocessing
import os
import shutil
import signal
import socket
import time
import zipfile

import pytest

from fcso.errors import ConfigError, MeshError
from fcsod.bus.messages import DecisionRecord, InputFile, LogRecord, OutputFilesRecord, StateChangeRecord, StoredMessage
from fcsod.config import JobManifest, LimitsConfig, McapConfig, PartEntry
from fcsod.job.events import WorkerReady
from fcsod.job.inputs import check_parts, hash_inputs, job_id, job_inputs
from fcsod.job.process import worker_main
from fcsod.record.audit import audit
from fcsod.record.decision import record_decision
from fcsod.record.recorder import (
    TOPIC_DECISION,
    TOPIC_LOG,
    TOPIC_OUTPUTS,
    TOPIC_STATE,
    Recorder,
    read_record,
    salvage,
)
from fcsod.service.journal import Journal, stored_messages
from fcsod.service.systemd import notify, watchdog_interval
from fcsod.service.watcher import FolderWatcher, Readiness
from fcsod.storage import file_sha256
from tests.conftest import HANG_GUARD_S
from tests.fcsod_helpers import DATA

CUBE = DATA / "20mm-xyz-cube.stl"


def _identity(folder):
    inputs = job_inputs(folder)
    return job_id(folder.name, hash_inputs(folder, inputs, 10**9))


def test_job_id_follows_folder_name_and_content_not_times(tmp_path):
    folder = tmp_path / "Batch 7 (left)"
    folder.mkdir()
    shutil.copy(CUBE, folder / "cube.stl")
    first = _identity(folder)
    assert first.startswith("batch-7-left-") and len(first.rsplit("-", 1)[1]) == 12
    os.utime(folder / "cube.stl", (1, 1))
    assert _identity(folder) == first
    (folder / "cube.stl").write_bytes(CUBE.read_bytes() + b"\0")
    assert _identity(folder) != first
    other = tmp_path / "other"
    shutil.copytree(folder, other)
    assert _identity(other).rsplit("-", 1)[1] == _identity(folder).rsplit("-", 1)[1]


def test_manifest_inputs_and_missing_files(tmp_path):
    folder = tmp_path / "job"
    folder.mkdir()
    (folder / "job.toml").write_text('[[parts]]\nfile = "a.stl"\n[[parts]]\nfile = "sub/b.stl"\n')
    shutil.copy(CUBE, folder / "a.stl")
    (folder / "notes.txt").write_text("not an input")
    inputs = job_inputs(folder)
    assert inputs.files == ("job.toml", "a.stl") and inputs.missing == ("sub/b.stl",)
    (folder / "sub").mkdir()
    shutil.copy(CUBE, folder / "sub" / "b.stl")
    assert job_inputs(folder).missing == ()


def test_readiness_waits_for_settled_files_and_named_parts(tmp_path):
    # time is stepped by hand: what counts is the time the folder stayed unchanged, not how fast this machine is
    now = [0.0]
    folder = tmp_path / "job"
    folder.mkdir()
    (folder / "job.toml").write_text('[[parts]]\nfile = "a.stl"\n')
    readiness = Readiness(settle_seconds=0.3, clock=lambda: now[0])
    readiness.touch(folder)
    for _ in range(5):
        now[0] += 1.0
        assert readiness.poll() == [], "ready although the manifest names a missing part"
    with open(folder / "a.stl", "wb") as stream:
        stream.write(CUBE.read_bytes()[:1000])
        stream.flush()
        assert readiness.poll() == []
        now[0] += 0.2
        assert readiness.poll() == [], "ready 0.2 s after a change with settle_seconds = 0.3"
        stream.write(CUBE.read_bytes()[1000:])
    # a size change is seen whatever the file system's mtime resolution
    assert readiness.poll() == []
    now[0] += 0.2
    assert readiness.poll() == [], "ready although the file changed 0.2 s ago"
    now[0] += 0.2
    ready = readiness.poll()
    assert [r.folder for r in ready] == [folder]
    assert readiness.pending == []


@pytest.mark.parametrize("polling", [False, True])
def test_watcher_reports_changed_job_folders(tmp_path, polling):
    watcher = FolderWatcher([tmp_path], polling=polling, poll_interval_seconds=0.2)
    watcher.start()
    try:
        (tmp_path / "job").mkdir()
        (tmp_path / ".hidden").mkdir()
        (tmp_path / "job" / "a.stl").write_bytes(b"x")
        (tmp_path / ".hidden" / "a.stl").write_bytes(b"x")
        changed = set()
        deadline = time.monotonic() + HANG_GUARD_S
        while (tmp_path / "job") not in changed and time.monotonic() < deadline:
            changed |= watcher.take_changed()
            time.sleep(0.1)
        assert changed == {tmp_path / "job"}
        assert watcher.all_folders() == [tmp_path / "job"]
        # a lost-events warning from watchdog asks for a rescan
        logging.getLogger("watchdog.observers.inotify_c").warning(
            "Inotify queue overflowed; filesystem events were lost"
        )
        assert watcher.rescan_requested.is_set()
    finally:
        watcher.stop()


def _manifest_folder(tmp_path, manifest_parts):
    folder = tmp_path / "job"
    folder.mkdir()
    shutil.copy(CUBE, folder / "cube.stl")
    return folder, JobManifest(parts=[PartEntry(file=f) for f in manifest_parts])


def test_paths_that_leave_the_folder_fail(tmp_path):
    folder, manifest = _manifest_folder(tmp_path, ["../outside.stl"])
    shutil.copy(CUBE, tmp_path / "outside.stl")
    with pytest.raises(ConfigError, match=r"parts\.0\.file: '\.\./outside\.stl': path leaves the job folder"):
        check_parts(folder, manifest, LimitsConfig())
    (folder / "link.stl").symlink_to(tmp_path / "outside.stl")
    for manifest in (JobManifest(parts=[PartEntry(file="link.stl")]), JobManifest()):
        with pytest.raises(ConfigError, match="symlink pointing outside the job folder"):
            check_parts(folder, manifest, LimitsConfig())
    with pytest.raises(ConfigError, match="leaves the job folder"):
        check_parts(folder, JobManifest(parts=[PartEntry(file="/etc/passwd")]), LimitsConfig())
    (folder / "link.stl").unlink()
    (folder / "inner.stl").symlink_to(folder / "cube.stl")
    assert [p.entry.file for p in check_parts(folder, JobManifest(), LimitsConfig())] == ["cube.stl", "inner.stl"]


def test_size_limits_and_zip_bomb_are_refused_before_parsing(tmp_path):
    folder, manifest = _manifest_folder(tmp_path, ["cube.stl"])
    with pytest.raises(MeshError, match="limits.max_faces"):
        check_parts(folder, manifest, LimitsConfig(max_faces=100))
    with pytest.raises(MeshError, match="limits.max_file_bytes"):
        check_parts(folder, manifest, LimitsConfig(max_file_bytes=1000))
    with zipfile.ZipFile(folder / "bomb.3mf", "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("3D/3dmodel.model", b"\0" * 20_000_000)
    bomb = JobManifest(parts=[PartEntry(file="bomb.3mf")])
    with pytest.raises(MeshError, match="zip bomb"):
        check_parts(folder, bomb, LimitsConfig())
    with pytest.raises(MeshError, match="max_3mf_uncompressed_bytes"):
        check_parts(folder, bomb, LimitsConfig(max_3mf_uncompressed_bytes=1_000_000))
    (folder / "broken.3mf").write_bytes(b"PK not a zip")
    with pytest.raises(MeshError, match="not a valid 3MF"):
        check_parts(folder, JobManifest(parts=[PartEntry(file="broken.3mf")]), LimitsConfig())
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(MeshError, match="no mesh file"):
        check_parts(empty, JobManifest(), LimitsConfig())


def test_journal_runs_a_job_once_and_requeues_after_a_crash(tmp_path):
    journal = Journal(tmp_path / "j.sqlite3")
    assert journal.add("a-1", "/w/a", "t0") and not journal.add("a-1", "/w/a", "t1")
    journal.mark_running("a-1", "t2")
    journal.close()
    reopened = Journal(tmp_path / "j.sqlite3")
    assert reopened.requeue_running() == ["a-1"]
    row = reopened.mark_running("a-1", "t3")
    assert (row.state, row.attempt) == ("running", 2)
    row = reopened.mark_finished("a-1", "failed", "t4", "bad mesh")
    assert (row.state, row.error, row.finished_at) == ("failed", "bad mesh", "t4")
    reopened.store_message(StoredMessage("a-1", "status", "k/a-1/status", "application/json", b"{}", None, None))
    reopened.store_message(StoredMessage("a-1", "status", "k/a-1/status", "application/json", b'{"v":2}', None, None))
    assert [m.payload for m in stored_messages(tmp_path / "j.sqlite3")] == [b'{"v":2}']


def test_a_journal_made_before_the_held_state_is_upgraded_keeping_its_rows(tmp_path):
    import sqlite3

    path = tmp_path / "j.sqlite3"
    old_schema = (
        "CREATE TABLE jobs (job_id TEXT PRIMARY KEY, folder TEXT NOT NULL, state TEXT NOT NULL CHECK (state IN "
        "('queued', 'running', 'done', 'failed')), attempt INTEGER NOT NULL DEFAULT 0, queued_at TEXT, started_at "
        "TEXT, finished_at TEXT, error TEXT);"
        "CREATE TABLE verifications (job_id TEXT PRIMARY KEY REFERENCES jobs (job_id), state TEXT NOT NULL, attempt "
        "INTEGER NOT NULL DEFAULT 1, started_at TEXT, finished_at TEXT, error TEXT);"
        "CREATE TABLE requests (request_id INTEGER PRIMARY KEY AUTOINCREMENT, job_id TEXT NOT NULL, action TEXT NOT "
        "NULL CHECK (action IN ('retry', 'cancel')), requested_at TEXT NOT NULL, handled_at TEXT, accepted INTEGER, "
        "outcome TEXT);"
        "INSERT INTO jobs VALUES ('a-1', '/w/a', 'done', 1, 't0', 't1', 't2', NULL);"
        "INSERT INTO verifications VALUES ('a-1', 'done', 1, 't2', 't3', NULL);"
    )
    with sqlite3.connect(path) as db:
        db.executescript(old_schema)
    journal = Journal(path)
    assert journal.get("a-1").state == "done" and journal.verification("a-1").state == "done"
    journal.add("b-2", "/w/b", "t4")
    journal.mark_running("b-2", "t5")
    assert journal.mark_finished("b-2", "held", "t6", "misses the policy").state == "held"
    from fcsod.service.journal import read_request, submit_request

    journal.close()
    assert submit_request(path, "b-2", "approve", "t7", "ana") == 1
    # the request says who asked: a column the old table did not have
    assert read_request(path, 1).requested_by == "ana"
    with sqlite3.connect(path) as db:
        # the verifications table still refers to the jobs table
        assert (
            "REFERENCES jobs" in db.execute("SELECT sql FROM sqlite_master WHERE name = 'verifications'").fetchone()[0]
        )
        assert db.execute("PRAGMA foreign_key_check").fetchall() == []


def test_an_operators_decision_is_recorded_and_the_audit_checks_the_files_it_left(tmp_path):
    """A held job's record and files, then a rejection: the record holds every message it had plus the decision
    and the failed state; the audit no longer asks for the removed build.held.3mf and still checks build.3mf."""
    files = {"build.3mf": b"parts alone", "build.held.3mf": b"parts and fingers"}
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
    recorder = Recorder(tmp_path / "job.mcap", "zstd", 4096)
    recorder.write(TOPIC_STATE, StateChangeRecord(job_id="j", state="held", at="t1", error="missed the policy"))
    recorder.write(
        TOPIC_OUTPUTS,
        OutputFilesRecord(
            job_id="j",
            files=[InputFile(path=n, size_bytes=len(d), sha256=file_sha256(tmp_path / n)) for n, d in files.items()],
        ),
    )
    recorder.finish()
    before = read_record(tmp_path / "job.mcap")
    decision = DecisionRecord(
        job_id="j", decision="rejected", by="ana", requested_at="t2", at="t3", files=[], removed=["build.held.3mf"]
    )
    record_decision(tmp_path, decision, "rejected by the operator", McapConfig())
    (tmp_path / "build.held.3mf").unlink()
    after = read_record(tmp_path / "job.mcap")
    assert not after.truncated
    assert [(m.topic, m.data) for m in after.messages[: len(before.messages)]] == [
        (m.topic, m.data) for m in before.messages
    ]
    assert after.of(TOPIC_DECISION) == [decision.model_dump(mode="json")]
    assert [(s["state"], s["error"]) for s in after.of(TOPIC_STATE)] == [
        ("held", "missed the policy"),
        ("failed", "rejected by the operator"),
    ]
    story = audit(tmp_path / "job.mcap", verify_dir=tmp_path)
    assert story.problems == [] and "rejected by ana at t3" in story.lines
    (tmp_path / "build.3mf").write_bytes(b"changed")
    assert [p for p in audit(tmp_path / "job.mcap", verify_dir=tmp_path).problems if "build.3mf: sha256" in p]


def test_cut_off_record_is_read_up_to_the_cut_and_salvaged(tmp_path):
    path = tmp_path / "job.mcap"
    recorder = Recorder(path, "lz4", 1024)
    recorder.write(TOPIC_STATE, StateChangeRecord(job_id="j", state="running", at="t"))
    for number in range(30):
        recorder.write(TOPIC_LOG, LogRecord(level="info", message=f"line {number}"))
    recorder.flush()
    recorder.write(TOPIC_LOG, LogRecord(level="info", message="after the last flush"))
    # the process dies here: no summary, no footer, the last chunk never written
    cut = tmp_path / "cut.mcap"
    shutil.copy(path, cut)
    recorder.finish()
    content = read_record(cut)
    assert content.truncated and len(content.messages) == 31
    assert content.of(TOPIC_LOG)[-1]["message"] == "line 29"
    story = audit(cut, verify_dir=tmp_path)
    assert any(line.startswith("TRUNCATED") for line in story.lines) and story.problems
    assert not read_record(path).truncated and len(read_record(path).messages) == 32

    salvaged = salvage(cut, tmp_path / "salvaged.mcap", "zstd", 4096)
    salvaged.write(TOPIC_STATE, StateChangeRecord(job_id="j", state="failed", at="t", error="worker died"))
    salvaged.finish()
    content = read_record(tmp_path / "salvaged.mcap")
    assert not content.truncated and [s["state"] for s in content.of(TOPIC_STATE)] == ["running", "failed"]


def test_sd_notify_sends_datagrams(tmp_path, monkeypatch):
    monkeypatch.delenv("NOTIFY_SOCKET", raising=False)
    assert notify("READY=1") is False
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    listener.bind(str(tmp_path / "n.sock"))
    monkeypatch.setenv("NOTIFY_SOCKET", str(tmp_path / "n.sock"))
    assert notify("READY=1")
    assert listener.recv(100) == b"READY=1"
    monkeypatch.setenv("WATCHDOG_USEC", "3000000")
    monkeypatch.setenv("WATCHDOG_PID", str(os.getpid()))
    assert watchdog_interval() == 1.5
    monkeypatch.setenv("WATCHDOG_PID", "1")
    assert watchdog_interval() is None
    listener.close()


def test_a_worker_ends_itself_when_the_daemons_life_line_ends_though_its_task_pipe_stays_open():
    # as the daemon starts one: forked by the fork server, so the daemon is not its parent
    context = multiprocessing.get_context("forkserver")
    life_line, daemon_end = context.Pipe(duplex=False)
    ours, theirs = context.Pipe(duplex=True)
    worker = context.Process(target=worker_main, args=(theirs, life_line), name="fcsod-worker")
    worker.start()
    theirs.close()
    try:
        assert ours.poll(HANG_GUARD_S) and isinstance(ours.recv(), WorkerReady)
        # the worker now waits for its task on a pipe that stays open: only the life line can end it
        daemon_end.close()
        worker.join(HANG_GUARD_S)
        assert worker.exitcode == -signal.SIGKILL
    finally:
        if worker.is_alive():
            worker.kill()
        ours.close()
