"""The daemon as Foxglove's users see it: its live server through Foxglove's own reference client."""

from __future__ import annotations

import base64
import fcntl
import json
import shutil
import subprocess

import pytest

from tests.conftest import HANG_GUARD_S
from tests.fcsod_helpers import (
    DATA,
    REPO,
    Process,
    decode_foxglove,
    drop_job,
    foxglove_messages,
    free_port,
    start_daemon,
    write_config,
)

CUBE = DATA / "20mm-xyz-cube.stl"

#: Foxglove's reference WebSocket client (the one Lichtblick builds on) and the WebSocket package it runs on in Node.
NPM_PACKAGES = ("@foxglove/ws-protocol@0.8.0", "ws@8.23.1")

#: Where npm installs them, once: the repository's ignored build folder.
NPM_PREFIX = REPO / "build" / "npm"


def reference_client_modules() -> str:
    """The node_modules folder holding :data:`NPM_PACKAGES`, installed by npm from the registry on the first run."""
    if shutil.which("node") is None or shutil.which("npm") is None:
        pytest.fail("Node.js and npm are needed: make node")
    NPM_PREFIX.mkdir(parents=True, exist_ok=True)
    with open(NPM_PREFIX / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        installed = NPM_PREFIX / "installed.json"
        if not installed.is_file() or json.loads(installed.read_text()) != list(NPM_PACKAGES):
            subprocess.run(
                ["npm", "install", "--no-audit", "--no-fund", "--prefix", str(NPM_PREFIX), *NPM_PACKAGES],
                check=True,
                timeout=HANG_GUARD_S,
            )
            installed.write_text(json.dumps(list(NPM_PACKAGES)))
    return str(NPM_PREFIX / "node_modules")


def test_foxglove_reference_client_receives_the_scene(tmp_path):
    """``@foxglove/ws-protocol`` offers only ``foxglove.websocket.v1`` (as Lichtblick does): the live server accepts it,
    and the client subscribes to ``/scene`` and receives a job's scene, the bytes of its record."""
    modules = reference_client_modules()
    foxglove_port = free_port()
    config = write_config(
        tmp_path, free_port(), extra=f'[foxglove]\nenabled = true\nlisten = "127.0.0.1:{foxglove_port}"\n'
    )
    daemon = start_daemon(config)
    client = None
    try:
        client = Process(
            [f"ws://127.0.0.1:{foxglove_port}", "/scene", "1"],
            env={"NODE_PATH": modules},
            program=["node", str(REPO / "tests" / "foxglove_ws_client.js")],
        )
        subscribed = client.wait_for(lambda v: isinstance(v, dict) and v["event"] in ("subscribed", "error", "close"))
        assert subscribed == {
            "event": "subscribed",
            "topic": "/scene",
            "schemaName": "foxglove.SceneUpdate",
            "encoding": "protobuf",
        }
        daemon.wait_for(
            lambda v: (
                isinstance(v, dict) and v.get("message") == "Foxglove client subscribed" and v["topic"] == "/scene"
            )
        )
        drop_job(tmp_path / "watch" / "cube", {"cube.stl": CUBE})
        message = client.wait_for(lambda v: isinstance(v, dict) and v["event"] in ("message", "error", "close"))
        done = daemon.wait_for(lambda v: isinstance(v, dict) and v.get("state") in ("done", "failed", "held"))
        client.wait_for(lambda v: isinstance(v, dict) and v["event"] == "close")
        assert client.popen.wait(timeout=HANG_GUARD_S) == 0
    finally:
        if client is not None:
            client.stop()
        assert daemon.stop() == 0

    events = [v["event"] for v in client.json_lines()]
    assert events == ["open", "serverInfo", "subscribed", "message", "close"], client.lines
    assert done["state"] == "done", done
    scene = decode_foxglove("foxglove.SceneUpdate", base64.b64decode(message["data"]))
    assert scene == foxglove_messages(tmp_path / "out" / done["job_id"] / "job.mcap")["/scene"][0]
