"""Build placement in the daemon: ``fcsod run`` and ``fcsod subscribe`` as separate processes, real job folders.

Each job's ``build.3mf`` must reload (trimesh and :func:`fcsod.plate.build3mf.read_build`)
with the items and transforms of the placement section of ``report.json``,
which the MCAP record and zenoh carry too.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from fcso import DesignConfig
from fcso.errors import ConfigError
from fcsod.cli import main
from fcsod.config import load_daemon_config, parse_manifest
from fcsod.plate.build3mf import BuildItem, read_build, write_build_3mf
from fcsod.record.recorder import TOPIC_PLACEMENT, TOPIC_SCENE, read_record
from tests.fcsod_helpers import (
    DATA,
    drop_job,
    finished,
    foxglove_messages,
    free_port,
    start_daemon,
    start_subscriber,
    without_design_notes,
    write_config,
)

CUBE = DATA / "20mm-xyz-cube.stl"
#: 1.34 x 1 x 1.35 inches: 34 x 25.4 x 34.3 mm
ANGLE_BLOCK = DATA / "angle_block.STL"


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    """A running daemon (default build volume) and a subscriber connected before any job."""
    base = tmp_path_factory.mktemp("placement")
    config = write_config(base, free_port())
    daemon = start_daemon(config)
    subscriber = start_subscriber(config)
    yield {"base": base, "daemon": daemon, "subscriber": subscriber}
    subscriber.stop()
    assert daemon.stop() == 0, "daemon did not stop cleanly on SIGTERM"


def _live(subscriber, job_id: str, topic: str) -> dict:
    """The subscriber's line of the job's live message of ``topic`` (``body`` holds a JSON payload)."""
    return next(
        v
        for v in subscriber.json_lines()
        if v.get("job_id") == job_id and v["topic"] == topic and v["source"] == "live"
    )


def _on_floor(mesh: trimesh.Trimesh, x_mm: float, y_mm: float, floor_mm: float = 10.0) -> np.ndarray:
    """Translation putting the mesh's bounding box's lower corner at (x, y, floor), mm."""
    transform = np.eye(4)
    transform[:3, 3] = np.array([x_mm, y_mm, floor_mm]) - mesh.bounds[0]
    return transform


def _check_build_file(out: Path, placement: dict) -> None:
    """``build.3mf`` reloads with trimesh and read_build holding exactly the placement's items and transforms."""
    expected = {item["name"]: np.asarray(item["transform"]) for item in placement["items"]}
    scene = trimesh.load(str(out / "build.3mf"), file_type="3mf", force="scene")
    nodes = {node: scene.graph[node][0] for node in scene.graph.nodes_geometry}
    assert sorted(nodes) == sorted(expected)
    for name, transform in expected.items():
        assert np.allclose(nodes[name], transform, atol=1e-9), name
    build = read_build([out / "build.3mf"])
    assert len(build.items) == len(expected) and build.placed
    for item in build.items:
        assert np.allclose(item.transform, expected[item.name.removeprefix("build/")], atol=1e-9), item.name


def _record_placement(out: Path) -> dict:
    record = read_record(out / "job.mcap")
    assert not record.truncated
    assert record.channels[TOPIC_PLACEMENT] == "fcsod.PlacementReport"
    (placement,) = record.of(TOPIC_PLACEMENT)
    build_scene = foxglove_messages(out / "job.mcap")[TOPIC_SCENE][-1]["entities"][0]
    assert build_scene["id"] == "build" and len(build_scene["triangles"]) == placement["finger_copies_placed"]
    return placement


def test_loose_parts_are_packed_with_the_fingers(cell, capsys):
    base, subscriber = cell["base"], cell["subscriber"]
    manifest = '[[parts]]\nfile = "cube.stl"\nquantity = 2\n\n[[parts]]\nfile = "angle_block.STL"\nunits = "inch"\n'
    drop_job(base / "watch" / "loose", {"job.toml": manifest, "cube.stl": CUBE, "angle_block.STL": ANGLE_BLOCK})
    done = finished(subscriber, "loose")
    assert done["body"]["state"] == "done" and without_design_notes(done["body"]["warnings"]) == [], done
    job_id = done["job_id"]
    out = base / "out" / job_id
    assert "build.3mf" in done["body"]["outputs"]

    report = json.loads((out / "report.json").read_text())
    placement = report["placement"]
    assert placement["mode"] == "pack" and placement["fingers_fit"] and placement["all_items_placed"]
    kinds = [item["kind"] for item in placement["items"]]
    assert kinds == ["part"] * 3 + ["finger"] * 2, "three part items (cube twice) and the default two finger copies"
    assert all(item["placed_by"] == "placer" for item in placement["items"])
    assert all(item["nearest_distance_mm"] >= placement["spacing_mm"] - 0.1 for item in placement["items"])
    assert placement["build_height_mm"] > 0 and 0 < placement["packing_density"] < 1
    _check_build_file(out, placement)
    assert _record_placement(out) == placement
    page = (out / "report.html").read_text()
    assert "<h2>Build placement</h2>" in page and str(placement["build_height_mm"]) in page

    message = _live(subscriber, job_id, "placement")["body"]
    assert message["fingers_fit"] is True and message["file"] == "build.3mf"
    assert (
        message["build_height_mm"] == placement["build_height_mm"]
        and message["packing_density"] == placement["packing_density"]
    )
    assert message["extra_height_needed_mm"] is None

    assert main(["audit", str(out / "job.mcap"), "--verify", str(out)]) == 0
    text = capsys.readouterr().out
    assert "placement (pack, volume 380 x 284 x 380 mm): fingers fit, 2 of 2 finger copies placed, 5 items" in text
    assert f"published fcso/test/jobs/{job_id}/placement" in text and "verified output" in text and "build.3mf" in text


def test_3mf_build_keeps_its_parts_and_gets_the_fingers(cell, tmp_path):
    base, subscriber = cell["base"], cell["subscriber"]
    cube = trimesh.load(str(CUBE))
    angle = trimesh.load(str(ANGLE_BLOCK)).apply_scale(25.4)
    given = [
        BuildItem("cube", cube, _on_floor(cube, 20.0, 20.0)),
        BuildItem("cube_2", cube, _on_floor(cube, 60.0, 20.0)),
        BuildItem("angle", angle, _on_floor(angle, 100.0, 20.0)),
    ]
    plate = write_build_3mf(given, tmp_path / "plate.3mf")
    drop_job(base / "watch" / "placed-build", {"plate.3mf": plate})
    done = finished(subscriber, "placed-build")
    assert done["body"]["state"] == "done" and without_design_notes(done["body"]["warnings"]) == [], done
    out = base / "out" / done["job_id"]

    report = json.loads((out / "report.json").read_text())
    assert sorted(part["name"] for part in report["parts"]) == ["plate/angle", "plate/cube"], (
        "each distinct item mesh is designed once"
    )
    placement = report["placement"]
    assert placement["mode"] == "add_fingers" and placement["fingers_fit"]
    by_name = {item["name"]: item for item in placement["items"]}
    for item in given:
        placed = by_name[f"plate/{item.name}"]
        assert placed["placed_by"] == "build" and np.allclose(placed["transform"], item.transform, atol=1e-6), item.name
    fingers = [item for item in placement["items"] if item["kind"] == "finger"]
    assert len(fingers) == 2 and all(item["placed_by"] == "placer" for item in fingers)
    _check_build_file(out, placement)
    assert _record_placement(out) == placement
    assert _live(subscriber, done["job_id"], "placement")["body"]["mode"] == "add_fingers"


def test_fingers_that_do_not_fit_leave_the_design_delivered(cell):
    base, subscriber = cell["base"], cell["subscriber"]
    # room for the cube (20 mm + 10 mm wall margins) but not for a 19 x 20 x 47 mm finger beside or on it
    manifest = '[[parts]]\nfile = "cube.stl"\n\n[build]\nvolume_mm = [60, 60, 41]\n'
    drop_job(base / "watch" / "small-volume", {"job.toml": manifest, "cube.stl": CUBE})
    done = finished(subscriber, "small-volume")
    body = done["body"]
    assert body["state"] == "done", done
    out = base / "out" / done["job_id"]
    assert (out / "finger.stl").stat().st_size > 0 and (out / "build.3mf").is_file()
    design = _live(subscriber, done["job_id"], "design")
    assert design["sha256_ok"] is True and design["bytes"] == (out / "finger.stl").stat().st_size

    message = _live(subscriber, done["job_id"], "placement")["body"]
    assert message["fingers_fit"] is False and message["extra_height_needed_mm"] > 0
    assert without_design_notes(body["warnings"]) == [message["message"]] and "do not fit" in message["message"]
    report = json.loads((out / "report.json").read_text())
    placement = report["placement"]
    assert (
        placement["fingers_fit"] is False and placement["extra_height_needed_mm"] == message["extra_height_needed_mm"]
    )
    assert placement["volume_mm"] == [60, 60, 41] and message["message"] in report["warnings"]
    assert [item["kind"] for item in placement["items"]] == ["part"]
    _check_build_file(out, placement)
    assert _record_placement(out) == placement


def test_manifest_build_overrides_the_daemons_key_by_key(tmp_path):
    config = load_daemon_config(
        write_config(tmp_path, free_port(), extra="[build]\nspacing_mm = 3\nfinger_copies = 4\n")
    )
    assert (config.build.spacing_mm, config.build.finger_copies, config.build.volume_mm) == (3, 4, (380, 284, 380))
    text = (
        '[[parts]]\nfile = "a.stl"\ntransform = [1, 0, 0, 50, 0, 1, 0, 60, 0, 0, 1, 10, 0, 0, 0, '
        "1]\n\n[build]\nvolume_mm = [200, 200, 100]\n"
    )
    manifest = parse_manifest(text, "job.toml", DesignConfig(), config.build)
    build = manifest.build_config(config.build)
    assert (build.volume_mm, build.spacing_mm, build.finger_copies) == ((200, 200, 100), 3, 4)
    assert manifest.parts[0].transform == [[1, 0, 0, 50], [0, 1, 0, 60], [0, 0, 1, 10], [0, 0, 0, 1]]
    assert parse_manifest("", "job.toml", DesignConfig(), config.build).build_config(config.build) == config.build


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            '[[parts]]\nfile = "a.stl"\ntransform = [1, 0, 0]\n',
            "parts.0.transform: Value error, transform must be 16 numbers",
        ),
        ('[[parts]]\nfile = "a.stl"\ntransform = [0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]\n', "singular"),
        (
            '[[parts]]\nfile = "a.stl"\nquantity = 2\ntransform = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]\n',
            "a transform places one copy",
        ),
        (
            '[[parts]]\nfile = "plate.3mf"\nunits = "inch"\n',
            "a 3MF build carries its own items, unit and transforms: remove units",
        ),
        (
            "[build]\nvolume_mm = [30, 30, 30]\nwall_margin_mm = 15\n",
            "build: Value error, wall_margin_mm 15.0 leaves no room",
        ),
        ("[build]\nvolume = [300, 300, 300]\n", "build.volume: unknown key"),
    ],
)
def test_bad_build_settings_name_the_key(text, message):
    with pytest.raises(ConfigError) as error:
        parse_manifest(text, "batch/job.toml", DesignConfig())
    assert str(error.value).startswith("batch/job.toml: ") and message in str(error.value)
