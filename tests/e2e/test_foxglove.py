"""The daemon as Foxglove's users see it: its live server through Foxglove's own reference client, the frames and
grasps of its record, the layout it ships."""

from __future__ import annotations

import base64
import fcntl
import json
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import trimesh

from fcsod.record.recorder import read_record
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


@dataclass
class LiveJob:
    """A cube's job run by a daemon with its live server, watched by the reference client."""

    events: list[dict]
    done: dict
    record: Path


@pytest.fixture(scope="module")
def live_job(tmp_path_factory) -> LiveJob:
    """``@foxglove/ws-protocol`` offers only ``foxglove.websocket.v1`` (as Lichtblick does); it connects before the
    job, subscribes to ``/scene`` and closes after the first scene."""
    modules = reference_client_modules()
    base = tmp_path_factory.mktemp("live")
    foxglove_port = free_port()
    config = write_config(
        base, free_port(), extra=f'[foxglove]\nenabled = true\nlisten = "127.0.0.1:{foxglove_port}"\n'
    )
    daemon = start_daemon(config)
    client = None
    try:
        client = Process(
            [f"ws://127.0.0.1:{foxglove_port}", "/scene", "1"],
            env={"NODE_PATH": modules},
            program=["node", str(REPO / "tests" / "foxglove_ws_client.js")],
        )
        client.wait_for(lambda v: isinstance(v, dict) and v["event"] in ("subscribed", "error", "close"))
        daemon.wait_for(
            lambda v: (
                isinstance(v, dict) and v.get("message") == "Foxglove client subscribed" and v["topic"] == "/scene"
            )
        )
        drop_job(base / "watch" / "cube", {"cube.stl": CUBE})
        client.wait_for(lambda v: isinstance(v, dict) and v["event"] in ("message", "error", "close"))
        done = daemon.wait_for(lambda v: isinstance(v, dict) and v.get("state") in ("done", "failed", "held"))
        client.wait_for(lambda v: isinstance(v, dict) and v["event"] == "close")
        assert client.popen.wait(timeout=HANG_GUARD_S) == 0
    finally:
        if client is not None:
            client.stop()
        assert daemon.stop() == 0
    assert done["state"] == "done", done
    return LiveJob(client.json_lines(), done, base / "out" / done["job_id"] / "job.mcap")


def test_foxglove_reference_client_receives_the_scene(live_job):
    """The live server accepts the reference client's subprotocol; it receives the job's scene, the bytes of its
    record, and reports no error (no message it cannot read)."""
    events = live_job.events
    assert [v["event"] for v in events] == ["open", "serverInfo", "advertised", "subscribed", "message", "close"]
    subscribed, message = events[3], events[4]
    assert subscribed == {
        "event": "subscribed",
        "topic": "/scene",
        "schemaName": "foxglove.SceneUpdate",
        "encoding": "protobuf",
    }
    scene = decode_foxglove("foxglove.SceneUpdate", base64.b64decode(message["data"]))
    assert scene == foxglove_messages(live_job.record)["/scene"][0]


def matrix(transform: dict) -> np.ndarray:
    """4x4 of a decoded ``foxglove.FrameTransform`` (translation in m as given)."""
    rotation = transform.get("rotation", {})
    result = trimesh.transformations.quaternion_matrix([rotation.get(k, 0.0) for k in "wxyz"])
    result[:3, 3] = [transform.get("translation", {}).get(k, 0.0) for k in "xyz"]
    return result


def test_frames_put_parts_grasps_and_fingers_in_one_tree(live_job):
    """``/tf`` (foxglove.FrameTransforms) of the record: world -> the part's resting frame (the ROS 2 PoseArray's) ->
    its grasp's TCP -> both fingers, and world -> build volume -> each placed item; the scene draws the part in its
    resting frame and the grasp's arrow and label in the TCP's, where the recorded grasp says."""
    messages = foxglove_messages(live_job.record)
    record = read_record(live_job.record)
    parents = {}
    transforms = {}
    for message in messages["/tf"]:
        for transform in message["transforms"]:
            parents[transform["child_frame_id"]] = transform["parent_frame_id"]
            transforms[transform["child_frame_id"]] = matrix(transform)

    def root(frame: str) -> str:
        seen = [frame]
        while frame in parents:
            frame = parents[frame]
            assert frame not in seen, f"a cycle through {frame}"
            seen.append(frame)
        return frame

    assert {root(frame) for frame in parents} == {"world"}
    (grasps,) = [m["grasps"] for m in record.of("/design/grasps")]
    (grasp,) = grasps
    rest = f"fcso_{grasp['part']}_rest{grasp['pose_index']}"
    assert parents[rest] == "world"
    assert parents[f"{rest}_grasp"] == rest
    assert parents[f"{rest}_finger_plus"] == parents[f"{rest}_finger_minus"] == f"{rest}_grasp"
    tcp = transforms[f"{rest}_grasp"]
    assert np.allclose(tcp[:3, 3], np.asarray(grasp["position_mm"]) / 1000.0, atol=1e-6)
    assert np.allclose(tcp[:3, :3], trimesh.transformations.quaternion_matrix(grasp["quaternion_wxyz"])[:3, :3])
    # the two fingers' frames are half a turn apart about the approach (the TCP's z), on either side of the part
    plus, minus = transforms[f"{rest}_finger_plus"], transforms[f"{rest}_finger_minus"]
    half_turn = trimesh.transformations.rotation_matrix(np.pi, [0.0, 0.0, 1.0])
    assert np.allclose(minus[:3, :3], (half_turn @ plus)[:3, :3], atol=1e-6)
    assert parents["fcso_build"] == "world"
    placed = [frame for frame, parent in parents.items() if parent == "fcso_build"]
    assert any("cube" in frame for frame in placed) and any("finger" in frame for frame in placed), placed

    design_scene = messages["/scene"][0]
    by_id = {entity["id"]: entity for entity in design_scene["entities"]}
    assert by_id["scenario-0"]["frame_id"] == rest
    grasp_entity = by_id["grasp-0"]
    assert grasp_entity["frame_id"] == f"{rest}_grasp"
    (arrow,) = grasp_entity["arrows"]
    (label,) = grasp_entity["texts"]
    assert grasp["part"] in label["text"]
    # the arrow ends at the TCP, pointing along its z (the approach)
    pose = matrix({"translation": arrow["pose"]["position"], "rotation": arrow["pose"]["orientation"]})
    length = arrow["shaft_length"] + arrow["head_length"]
    assert np.allclose(pose[:3, :3] @ [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], atol=1e-6)
    assert np.allclose(pose[:3, 3] + length * pose[:3, :3] @ [1.0, 0.0, 0.0], 0.0, atol=1e-6)
    build_scene = messages["/scene"][-1]
    assert build_scene["entities"][0]["frame_id"] == "fcso_build"


def test_layout_names_only_topics_fcsod_publishes(live_job):
    """``deploy/foxglove-layout.json``: a 3D panel on ``/scene`` in ``world`` and panels on the verification and the
    plan; every topic it names is one the live server advertised or the job's record holds."""
    layout = json.loads((REPO / "deploy" / "foxglove-layout.json").read_text())

    def named(value) -> set[str]:
        if isinstance(value, dict):
            found = {value["topicPath"]} if "topicPath" in value else set()
            found |= set(value.get("topics", {})) if isinstance(value.get("topics"), dict) else set()
            return found.union(*(named(v) for v in value.values()))
        if isinstance(value, list):
            return set().union(*(named(v) for v in value))
        return set()

    topics = named(layout["configById"])
    panels = {key.partition("!")[0] for key in layout["configById"]}
    assert {"3D", "RawMessages", "Table"} <= panels
    assert {"/scene", "/fcsod/verification", "/fcsod/plan"} <= topics
    (advertised,) = [v["topics"] for v in live_job.events if v["event"] == "advertised"]
    recorded = set(read_record(live_job.record).channels)
    assert topics <= set(advertised) | recorded, topics - set(advertised) - recorded
    assert layout["configById"]["3D!fcsod-job"]["followTf"] == "world"
