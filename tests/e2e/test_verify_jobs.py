"""fcsod with [verify]: the design is done and published first, its verification follows on zenoh, in the journal and in
MCAP; a kill -9 during it runs it again after the restart, once, without simulating again the grasps it had
simulated; a time limit publishes it as failed.
"""

from __future__ import annotations

import contextlib
import getpass
import hashlib
import io
import json
import re
import signal
import sqlite3
import time
import urllib.request

import pytest

from examples.sim_parts import ridged_block
from fcsod.cli import main as fcsod_main
from fcsod.record.recorder import (
    TOPIC_BUS,
    TOPIC_DECISION,
    TOPIC_STATE,
    TOPIC_VERIFICATION,
    TOPIC_VERIFICATION_SCENE,
    VERIFICATION_RECORD_NAME,
    read_record,
)
from tests.conftest import HANG_GUARD_S, process_running
from tests.fcsod_helpers import (
    SLOW_VERIFY,
    drop_job,
    finished,
    foxglove_messages,
    free_port,
    start_daemon,
    start_subscriber,
    write_config,
)

MANIFEST = '[[parts]]\nfile = "ridged.stl"\n\n[sampler]\nyaw_deg = [0]\nface_yaws = false\n'


def _is(topic: str, job_id: str | None = None):
    return lambda v: isinstance(v, dict) and v.get("topic") == topic and job_id in (None, v.get("job_id"))


def test_kill_during_verification_then_restart_verifies_once_published_recorded_and_answered(tmp_path):
    port = free_port()
    # the first daemon's verification runs for hours, so it is surely running when the daemon is killed;
    # the restarted daemon's quick one finishes
    config = write_config(tmp_path, port, verify=SLOW_VERIFY)
    part = tmp_path / "ridged.stl"
    ridged_block().export(part)
    first = start_daemon(config)
    subscriber = start_subscriber(config)
    try:
        drop_job(tmp_path / "watch" / "ridged", {"job.toml": MANIFEST, "ridged.stl": part})
        done = finished(subscriber, "ridged")
        assert done["body"]["state"] == "done", done
        job_id = done["job_id"]
        started = first.wait_for(lambda v: isinstance(v, dict) and v.get("message") == "job started")
        first.wait_for(lambda v: isinstance(v, dict) and v.get("message") == "verification: started")
        # killed once both fingers' nominal grasps and first two trials are judged: each grasp's outcome is in the
        # cache before it is judged, and the restarted daemon's two trials are these (the same seeded start errors)
        first.wait_for(lambda v: isinstance(v, dict) and v.get("stage") == "verification" and v.get("done", 0) >= 6)
    finally:
        first.stop(signal.SIGKILL)
        subscriber.stop()
    # the design was published before its verification began
    assert subscriber.wait_for(_is("design", job_id))
    deadline = time.monotonic() + HANG_GUARD_S
    while process_running(started["worker_pid"]) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not process_running(started["worker_pid"]), "the worker outlived the killed daemon"
    out = tmp_path / "out" / job_id
    journal = tmp_path / "state" / "journal.sqlite3"
    with sqlite3.connect(journal) as db:
        assert db.execute("SELECT state FROM jobs").fetchall() == [("done",)]
        assert db.execute("SELECT state, attempt FROM verifications").fetchall() == [("running", 1)]
        assert db.execute("SELECT count(*) FROM messages WHERE topic = 'verification'").fetchone() == (0,)
    assert not list(out.glob("*verification*")) and not list(out.glob(".*"))

    config = write_config(tmp_path, port, verify="enabled = true\ntop_k = 0\ntrials = 2")
    second = start_daemon(config)
    # the restarted daemon may verify before any subscriber connects: this one also asks for what was published
    # before it came (the journal's answer), so it does not depend on which is quicker
    subscriber = start_subscriber(config)
    try:
        message = subscriber.wait_for(_is("verification", job_id))
        # a late joiner gets it from the journal's queryable
        late = start_subscriber(config)
        try:
            answered = late.wait_for(_is("verification", job_id))
            assert answered["source"] != "live" and answered["body"] == message["body"]
        finally:
            late.stop()
    finally:
        subscriber.stop()
        assert second.stop() == 0
    # the job did not run again; its verification ran once more, and was published once: at most one message came
    # live, any answer from the journal is that one, and the record below holds one publication
    assert not any(v.get("message") == "job started" for v in second.json_lines())
    verifications = [v for v in subscriber.json_lines() if v.get("job_id") == job_id and v["topic"] == "verification"]
    assert sum(v["source"] == "live" for v in verifications) <= 1
    assert all(v["body"] == message["body"] for v in verifications)
    assert sum(v.get("message") == "verification started again" for v in second.json_lines()) == 1
    # the operator reads in the log that the resumed verification did not simulate everything again
    done_lines = [v["message"] for v in second.json_lines() if v.get("message", "").startswith("verification: design")]
    assert len(done_lines) == 1 and "grasps and holding pushes were read from the cache" in done_lines[0]
    with sqlite3.connect(journal) as db:
        assert db.execute("SELECT state, attempt FROM jobs").fetchall() == [("done", 1)]
        assert db.execute("SELECT state, attempt FROM verifications").fetchall() == [("done", 2)]
    body = message["body"]
    assert body["state"] == "done" and body["file"] == "verification.json" and len(body["scenarios"]) == 1
    scenario = body["scenarios"][0]
    # the carved V-grooves centre the ridged block; flat pads cannot
    assert scenario["success_rate"] == 1.0 and scenario["flat_success_rate"] < 1.0

    verification = json.loads((out / "verification.json").read_text())
    assert verification["scenarios"][0]["fcso"]["success_rate"] == scenario["success_rate"]
    # the verification resumed: the grasps the killed daemon had simulated were not simulated again; they are kept in
    # the daemon's state folder, beside its journal
    assert verification["scenarios"][0]["reused_simulations"] >= 6
    assert len(list((tmp_path / "state" / "verification-cache").glob("*.npz"))) >= 6
    assert len(verification["scenarios"][0]["fcso"]["trials"]) == 2
    # its section is a page of its own: report.html stays as job.mcap vouches for it
    assert (out / "verification.html").read_text().count("<!-- fcso verify -->") == 1
    assert "<!-- fcso verify -->" not in (out / "report.html").read_text()
    assert fcsod_main(["audit", str(out / "job.mcap"), "--verify", str(out)]) == 0
    record = read_record(out / VERIFICATION_RECORD_NAME)
    assert [v["passed"] for v in record.of(TOPIC_VERIFICATION)] == [body["passed"]]
    scenes = foxglove_messages(out / VERIFICATION_RECORD_NAME)[TOPIC_VERIFICATION_SCENE]
    assert len(scenes) > 10 and scenes[0]["entities"][0]["triangles"]
    assert [b["key_expr"].rsplit("/", 1)[-1] for b in record.of(TOPIC_BUS)] == ["verification"]
    assert not list(out.glob(".*")), "a temporary file was left behind"


def test_time_limit_publishes_failed_and_leaves_nothing_and_top_k_delivers_a_verified_candidate(tmp_path):
    port = free_port()
    # the daemon's verification: a million trials take hours on any machine, far over the 1 s limit
    config = write_config(tmp_path, port, verify=SLOW_VERIFY + "\ntime_limit_seconds = 1")
    part = tmp_path / "ridged.stl"
    ridged_block().export(part)
    # the second job chooses among its 2 best candidates by verification, before it is done
    choosing = MANIFEST + "\n[verify]\ntop_k = 2\ntrials = 2\n"
    daemon = start_daemon(config)
    subscriber = start_subscriber(config)
    try:
        drop_job(tmp_path / "watch" / "ridged", {"job.toml": MANIFEST, "ridged.stl": part})
        done = finished(subscriber, "ridged")
        job_id = done["job_id"]
        message = subscriber.wait_for(_is("verification", job_id))
        drop_job(tmp_path / "watch" / "choosing", {"job.toml": choosing, "ridged.stl": part})
        chosen_done = finished(subscriber, "choosing")
        chosen_id = chosen_done["job_id"]
        chosen_message = subscriber.wait_for(_is("verification", chosen_id))
    finally:
        subscriber.stop()
        assert daemon.stop() == 0
    assert done["body"]["state"] == "done", done
    body = message["body"]
    assert body["state"] == "failed" and not body["passed"] and body["file"] is None
    assert "time limit exceeded" in body["error"] and "verify.time_limit_seconds (1 s)" in body["error"]
    out = tmp_path / "out" / job_id
    assert not list(out.glob("*verification*")) and not list(out.glob(".*"))
    assert "<!-- fcso verify -->" not in (out / "report.html").read_text()
    with sqlite3.connect(tmp_path / "state" / "journal.sqlite3") as db:
        assert db.execute("SELECT state FROM jobs").fetchall() == [("done",), ("done",)]
        # the choosing job's verification is part of the job: nothing follows its done state
        rows = db.execute("SELECT job_id, state, error FROM verifications").fetchall()
    assert [(r[0], r[1]) for r in rows] == [(job_id, "failed")] and "time limit exceeded" in rows[0][2]

    # top_k: the first candidate by the measure passes, so it is the only one verified and is delivered
    assert chosen_done["body"]["state"] == "done", chosen_done
    lines = [v for v in subscriber.json_lines() if v.get("job_id") == chosen_id and v.get("source") == "live"]
    assert [v["topic"] for v in lines][-2:] == ["status", "verification"]
    body = chosen_message["body"]
    assert body["state"] == "done" and body["passed"] and body["file"] == "verification.json"
    # the verdict leads the message: designed against flat, every trial run, the weakest hold
    scenario = body["scenarios"][0]
    flat = round(scenario["flat_success_rate"] * 2)
    assert scenario["verdict"].startswith(f"designed 2/2, flat {flat}/2, ")
    assert body["verdict"] == f"verified: {scenario['part']} pose {scenario['pose_index']} {scenario['verdict']}"
    assert body["better_than_flat"] and body["not_held"] == []
    assert body["choice"].startswith(f"candidate {body['chosen_candidate']} (rank 1 by the measure")
    assert "the first whose every scenario passed, after 1 of 2 verified" in body["choice"]
    assert {"verification.json", "verification.mcap", "report.html"} <= set(chosen_done["body"]["outputs"])
    out = tmp_path / "out" / chosen_id
    assert json.loads((out / "report.json").read_text())["best"] == body["chosen_candidate"]
    assert "Delivered: candidate" in (out / "report.html").read_text()
    # job.mcap vouches for the verification's files and the page with its section
    assert fcsod_main(["audit", str(out / "job.mcap"), "--verify", str(out)]) == 0


SETS_MANIFEST = """
[[parts]]
file = "narrowing.stl"

[[parts]]
file = "widening.stl"

[finger_sets]
min_retained = 0.7

[verify]
enabled = true
top_k = 0
trials = 2
"""


def test_every_finger_set_of_a_job_is_verified_into_its_folder_and_on_its_key(tmp_path):
    # the conflicting knob parts of tests/fcso/test_sets.py need two fingers at min_retained 0.7
    from tests.fcso.test_sets import NARROWING, WIDENING

    port = free_port()
    config = write_config(tmp_path, port)
    files = {}
    for part in (NARROWING, WIDENING):
        files[f"{part.name}.stl"] = tmp_path / f"{part.name}.stl"
        part.mesh.export(files[f"{part.name}.stl"])
    daemon = start_daemon(config)
    subscriber = start_subscriber(config)
    try:
        drop_job(tmp_path / "watch" / "knobs", {"job.toml": SETS_MANIFEST, **files})
        done = finished(subscriber, "knobs")
        assert done["body"]["state"] == "done", done
        job_id = done["job_id"]
        subscriber.wait_for(
            lambda v: (
                isinstance(v, dict)
                and v.get("topic") == "verification/2"
                and v["job_id"] == job_id
                and v.get("signature_ok")
            ),
            240,
        )
        messages = {v["topic"]: v for v in subscriber.json_lines() if v.get("job_id") == job_id}
    finally:
        subscriber.stop()
        assert daemon.stop() == 0
    out = tmp_path / "out" / job_id
    for number, part in ((1, "narrowing"), (2, "widening")):
        body = messages[f"verification/{number}"]["body"]
        assert body["finger_set"] == number and body["file"] == f"set-{number}/verification.json"
        assert [s["part"] for s in body["scenarios"]] == [part]
        folder = out / f"set-{number}"
        written = json.loads((folder / "verification.json").read_text())
        assert written["scenarios"][0]["fcso"]["success_rate"] == body["scenarios"][0]["success_rate"]
        assert "<!-- fcso verify -->" in (folder / "verification.html").read_text()
        assert any(
            b["key_expr"].endswith(f"/verification/{number}")
            for b in read_record(folder / VERIFICATION_RECORD_NAME).of(TOPIC_BUS)
        )
    assert "verification" not in messages


def _object_names(build_3mf) -> list[str]:
    """The names of the objects of ``build.3mf``'s build items, read back from the file."""
    import zipfile

    from lxml import etree

    with zipfile.ZipFile(build_3mf) as archive:
        root = etree.fromstring(archive.read("3D/3dmodel.model"))
    ns = {"m": root.nsmap[None]}
    names = {o.get("id"): o.get("name") for o in root.iterfind(".//m:resources/m:object", ns)}
    return [names[item.get("objectid")] for item in root.iterfind(".//m:build/m:item", ns)]


def test_a_finger_that_misses_the_delivery_policy_is_held_unplaced_until_an_operator_approves_it(tmp_path):
    from examples.sim_parts import two_ridge_block, upright_grasp_settings

    port = free_port()
    # the paper's Q puts the paper's 20 mm pad on a horizontal ridge, where a displaced part slides
    # (tests/fcso/test_sim_choose.py)
    metrics_port = free_port()
    config = write_config(
        tmp_path,
        port,
        verify="enabled = true",
        design='[design.quality]\nmeasure = "paper"\n',
        extra=f'[metrics]\nenabled = true\nlisten = "127.0.0.1:{metrics_port}"\n',
    )
    mesh = two_ridge_block()
    part = tmp_path / "two-ridge.stl"
    mesh.export(part)
    settings = upright_grasp_settings(mesh)
    manifest = (
        '[[parts]]\nfile = "two-ridge.stl"\n\n'
        f"[poses]\ncount = 1\nselect = {settings['poses']['select']}\n\n"
        f"[sampler]\nlength_mm = 20.0\nyaw_deg = {settings['sampler']['yaw_deg']}\nface_yaws = false\n\n"
        '[verify]\ntop_k = 0\ntrials = 2\ndeliver = "verified"\n'
    )
    daemon = start_daemon(config)
    subscriber = start_subscriber(config)
    try:
        drop_job(tmp_path / "watch" / "ridges", {"job.toml": manifest, "two-ridge.stl": part})
        held = subscriber.wait_for(lambda v: _is("status")(v) and v["body"]["state"] in ("held", "done", "failed"))
        assert held["body"]["state"] == "held", held
        job_id = held["job_id"]
        verification = subscriber.wait_for(_is("verification", job_id))
        out = tmp_path / "out" / job_id
        held_names = _object_names(out / "build.3mf")
        held_audit = _audit(out)
        with sqlite3.connect(tmp_path / "state" / "journal.sqlite3") as db:
            journalled = db.execute("SELECT state FROM jobs").fetchall()
        with urllib.request.urlopen(f"http://127.0.0.1:{metrics_port}/metrics", timeout=HANG_GUARD_S) as reply:
            metrics = reply.read().decode()
        early = [v["topic"] for v in subscriber.json_lines() if v.get("job_id") == job_id and v.get("source") == "live"]
        assert fcsod_main(["approve", job_id[:12], "--config", str(config)]) == 0
        done = subscriber.wait_for(lambda v: _is("status", job_id)(v) and v["body"]["state"] == "done")
        grasps = subscriber.wait_for(_is("grasps", job_id))
    finally:
        subscriber.stop()
        assert daemon.stop() == 0
    assert "did not pass verification" in held["body"]["error"] and "fcsod approve" in held["body"]["error"]
    assert not verification["body"]["passed"] and verification["body"]["verdict"].startswith("not verified: ")
    assert journalled == [("held",)]
    # the verification made inside the design step is counted, and the held job is a state of its own
    assert 'fcsod_verifications_total{result="failed"} 1.0' in metrics
    assert 'fcsod_jobs{state="held"} 1.0' in metrics and 'fcsod_jobs_finished_total{state="held"} 1.0' in metrics
    # held: the build has the part, no finger; the finger's grasps and design are not published
    assert held_names == ["two-ridge"]
    assert not {"grasps", "design", "quality", "placement"} & set(early)
    # approved: the finger is in build.3mf, its grasps published, the job done
    assert done["body"]["error"] is None and "build.held.3mf" not in done["body"]["outputs"]
    # each grasp says how far the gripper opens before it comes down, which finger, the verdict and the job
    settings = json.loads((out / "report.json").read_text())["settings"]
    for grasp in grasps["body"]["grasps"]:
        opening = grasp["closing_width_mm"] + 2 * (settings["sampler"]["penetration_mm"] + 5.0)
        assert grasp["approach_opening_mm"] == pytest.approx(min(opening, settings["gripper"]["max_opening_mm"]))
        assert grasp["job_id"] == job_id and grasp["finger_set"] == 1 and grasp["verified"] is False
        assert re.match(r"not verified: designed [0-2]/2, flat [0-2]/2, ", grasp["verdict"]), grasp["verdict"]
    names = _object_names(out / "build.3mf")
    assert names[0] == "two-ridge" and names[1:] and all(n.startswith("fcso-finger") for n in names[1:])
    assert not (out / "build.held.3mf").exists()
    with sqlite3.connect(tmp_path / "state" / "journal.sqlite3") as db:
        assert db.execute("SELECT state, error FROM jobs").fetchall() == [("done", None)]
    # the record vouches for the files as they were held, and then as the approval left them: it holds who approved
    # and the new build.3mf's hash; a build.3mf changed afterwards fails the check
    assert held_audit[0] == 0, held_audit[1]
    record = read_record(out / "job.mcap")
    (approval,) = record.of(TOPIC_DECISION)
    assert (approval["decision"], approval["by"], approval["removed"]) == (
        "approved",
        getpass.getuser(),
        ["build.held.3mf"],
    )
    assert [(f["path"], f["sha256"]) for f in approval["files"]] == [
        ("build.3mf", hashlib.sha256((out / "build.3mf").read_bytes()).hexdigest())
    ]
    assert [s["state"] for s in record.of(TOPIC_STATE)][-2:] == ["held", "done"]
    approved_audit = _audit(out)
    assert approved_audit[0] == 0 and f"approved by {getpass.getuser()}" in approved_audit[1], approved_audit[1]
    with open(out / "build.3mf", "ab") as build:
        build.write(b"\0")
    tampered = _audit(out)
    assert tampered[0] == 1 and "PROBLEM: output" in tampered[1] and "build.3mf: sha256" in tampered[1], tampered[1]


def _audit(out) -> tuple[int, str]:
    """``fcsod audit --verify`` of a job's output folder: exit code and printed text."""
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = fcsod_main(["audit", str(out / "job.mcap"), "--verify", str(out)])
    return code, printed.getvalue()
