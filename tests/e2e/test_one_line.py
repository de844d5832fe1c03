"""What a user meets at the command line: no traceback, no noise, one line saying what to do (issue 47)."""

from __future__ import annotations

import socket
import sqlite3
import subprocess
import sys

import trimesh

from fcsod.bus.signing import daemon_signer, verify_key_path
from fcsod.config import load_daemon_config
from fcsod.record.recorder import Recorder
from fcsod.service.journal import Journal
from tests.conftest import HANG_GUARD_S
from tests.fcsod_helpers import DATA, REPO, Process, free_port, start_daemon, write_config


def _run(module: str, *args, shell_pipe: str | None = None) -> subprocess.CompletedProcess:
    command = [sys.executable, "-m", module, *map(str, args)]
    if shell_pipe is not None:
        command = ["sh", "-c", " ".join(f"'{c}'" for c in command) + f" | {shell_pipe}"]
    return subprocess.run(command, cwd=REPO, capture_output=True, text=True, timeout=HANG_GUARD_S)


def test_a_part_drawn_in_inches_fails_with_a_hint_naming_units(tmp_path):
    part = trimesh.load(DATA / "20mm-xyz-cube.stl")
    part.apply_scale(1 / 25.4)
    part.export(tmp_path / "cube-inch.stl")
    run = _run("fcso.cli", "design", tmp_path / "cube-inch.stl", "--out", tmp_path / "out")
    assert run.returncode == 2
    assert len(run.stderr.strip().splitlines()) == 1 and "Traceback" not in run.stderr
    assert "no valid grasp" in run.stderr and "load it with --units inch (x25.4)" in run.stderr


def test_fcso_design_verify_ends_without_nanobind_noise(tmp_path):
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "fcso.cli",
            "design",
            str(DATA / "20mm-xyz-cube.stl"),
            "--out",
            str(tmp_path / "out"),
            "--verify",
            "--trials",
            "1",
            "--quiet",
        ],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=HANG_GUARD_S,
        env={**__import__("os").environ, "FCSO_CACHE_DIR": str(tmp_path / "cache")},
    )
    assert run.returncode in (0, 3), run.stderr
    assert (tmp_path / "out" / "verification.json").is_file()
    assert "leaked" not in run.stderr and run.stderr == ""


def test_fcso_poses_help_explains_every_option():
    run = _run("fcso.cli", "poses", "--help")
    assert run.returncode == 0
    options = [line.split() for line in run.stdout.splitlines() if line.strip().startswith("--")]
    assert {o[0] for o in options} == {"--units", "--scale-to", "--repair"}
    # each option line carries its help text beyond the option and its metavar
    assert all(len(o) > 2 or (o[0] == "--repair" and len(o) > 1) for o in options), options


def test_fcsod_jobs_into_a_pipe_closed_early_is_silent(tmp_path):
    config = write_config(tmp_path, free_port())
    state = load_daemon_config(config).state.dir
    state.mkdir(parents=True, exist_ok=True)
    Journal(state / "journal.sqlite3").close()
    # more lines than a pipe holds, so the writer meets the closed pipe
    with sqlite3.connect(state / "journal.sqlite3") as db:
        db.executemany(
            "INSERT INTO jobs (job_id, folder, state, queued_at) VALUES (?, ?, 'queued', '2026-01-01T00:00:00Z')",
            [(f"job-{k:05d}", f"/watch/folder-{k:05d}" + "/x" * 40) for k in range(3000)],
        )
    run = _run("fcsod", "jobs", "--config", config, "--json", shell_pipe="head -1")
    assert run.stdout.count("\n") == 1 and '"job_id": "job-00000"' in run.stdout
    assert run.stderr == ""


def test_replay_where_the_daemon_listens_says_where_to_replay(tmp_path):
    port = free_port()
    config = write_config(tmp_path, port)
    daemon_signer(load_daemon_config(config))
    record = tmp_path / "job.mcap"
    Recorder(record, "zstd", 4096).finish()
    with socket.socket() as taken:
        # the daemon's endpoint, in use
        taken.bind(("127.0.0.1", port))
        taken.listen()
        run = _run("fcsod", "replay", record, "--config", config, "--wait", "0")
    assert run.returncode == 2
    assert len(run.stderr.strip().splitlines()) == 1 and "Traceback" not in run.stderr, run.stderr
    assert "--listen tcp/127.0.0.1:<free port>" in run.stderr


def test_subscribe_started_before_the_daemon_waits_for_it(tmp_path):
    port = free_port()
    config = write_config(tmp_path, port)
    daemon_signer(load_daemon_config(config))
    # a cell controller in client mode (as fcsod pki gives it), started before the print server
    zenoh_config = tmp_path / "cell.json5"
    zenoh_config.write_text(
        f'{{mode: "client", connect: {{endpoints: ["tcp/127.0.0.1:{port}"]}}, '
        "scouting: {multicast: {enabled: false}}}"
    )
    verify_key = verify_key_path(load_daemon_config(config))
    subscriber = Process(
        ["subscribe", "--config", str(config), "--zenoh-config", str(zenoh_config), "--verify-key", str(verify_key)]
    )
    try:
        subscriber.wait_for(lambda v: isinstance(v, str) and v.startswith("waiting for ") and "to listen" in v)
        daemon = start_daemon(config)
        try:
            subscriber.wait_for(lambda v: isinstance(v, dict) and v.get("daemon") == "alive")
        finally:
            assert daemon.stop() == 0
    finally:
        subscriber.stop()
