"""Print-ready as written (METHOD §9b): every delivered STL, read back from disk, is one watertight body.

Designs run with every ``[print]`` profile on the fixture parts and on two
parts built here whose carving once fell apart when written as float32 STL
(a knurled knob, a plate with an octagonal through-pocket). Each written
file is read back with trimesh as a slicer would read it (float32
coordinates, coincident vertices merged) and measured here, independently
of fcso's own measurement.
"""

from __future__ import annotations

import collections
import json
import subprocess
import sys

import manifold3d
import numpy as np
import pytest
import trimesh

import fcso
from examples.batch_demo import DEMO_10MM_PADS, batch_demo_part_files, batch_demo_settings
from examples.part_families import draw
from examples.sim_parts import two_ridge_block
from fcso.finger import without_zero_area_faces
from fcso.output.files import output_files
from tests.conftest import HANG_GUARD_S, REPO, data_path, small_config

PROFILES = ["custom", "mjf-pa12", "fdm-pla", "sla-resin"]
#: Smallest face area that counts as non-zero after the float32 read-back, mm².
MIN_FACE_AREA_MM2 = 1e-12


def _knob() -> trimesh.Trimesh:
    """A knurled knob: cylinder r = 12 mm, h = 20 mm, with 24 axial ridges 1.5 x 1 mm around it."""
    body = manifold3d.Manifold.cylinder(20.0, 12.0, circular_segments=64)
    ridges = [
        manifold3d.Manifold.cube([1.5, 1.0, 20.0]).translate([11.5, -0.5, 0.0]).rotate([0.0, 0.0, 15.0 * k])
        for k in range(24)
    ]
    return _trimesh(manifold3d.Manifold.batch_boolean([body, *ridges], manifold3d.OpType.Add))


def _octagon_plate() -> trimesh.Trimesh:
    """A 60 x 60 x 8 mm plate with an octagonal through-pocket (circumradius 12 mm)."""
    plate = manifold3d.Manifold.cube([60.0, 60.0, 8.0]).translate([-30.0, -30.0, 0.0])
    pocket = (
        manifold3d.Manifold.cylinder(12.0, 12.0, circular_segments=8)
        .translate([0.0, 0.0, -2.0])
        .rotate([0.0, 0.0, 22.5])
    )
    return _trimesh(plate - pocket)


def _trimesh(solid: manifold3d.Manifold) -> trimesh.Trimesh:
    mesh = solid.to_mesh()
    return trimesh.Trimesh(
        np.asarray(mesh.vert_properties[:, :3], dtype=np.float64), np.asarray(mesh.tri_verts), process=True
    )


#: name -> (how to get the mesh file, extra settings):
#: the built parts, then fixture parts of tests/data and examples/parts.
PARTS = {
    "knob": (_knob, {}),
    # the plate is wider than the default 50 mm opening
    "octagon_plate": (_octagon_plate, {"gripper": {"max_opening_mm": 80.0}}),
    "20mm-xyz-cube": (lambda: REPO / "examples" / "parts" / "20mm-xyz-cube.stl", {}),
    "DC-DC_case": (lambda: data_path("DC-DC_case.stl"), {}),
    "solar_tracker": (lambda: data_path("solar_tracker.stl"), {}),
}


#: Parts whose chosen pad is carved (not flat) with every profile, so the lead-in, clearance and opening are exercised.
CARVED = ("knob",)


def _read_back(path) -> trimesh.Trimesh:
    """The STL file as a slicer reads it: float32 coordinates, coincident vertices merged."""
    mesh = trimesh.load(path, file_type="stl", process=True)
    assert isinstance(mesh, trimesh.Trimesh), path
    return mesh


def _assert_one_body(mesh: trimesh.Trimesh, what: str) -> None:
    zero = int((mesh.area_faces <= MIN_FACE_AREA_MM2).sum())
    pieces = len(mesh.split(only_watertight=False))
    assert mesh.is_watertight, (
        f"{what}: open or non-manifold edges ({len(mesh.faces)} faces, {zero} of zero area, {pieces} pieces)"
    )
    assert zero == 0, f"{what}: {zero} zero-area faces of {len(mesh.faces)}"
    assert pieces == 1, f"{what}: {pieces} connected pieces"
    assert mesh.volume > 0, f"{what}: volume {mesh.volume}"


@pytest.fixture(scope="module")
def part_files(tmp_path_factory) -> dict:
    folder = tmp_path_factory.mktemp("parts")
    files = {}
    for name, (source, _) in PARTS.items():
        made = source()
        if isinstance(made, trimesh.Trimesh):
            path = folder / f"{name}.stl"
            made.export(path)
            files[name] = path
        else:
            files[name] = made
    return files


@pytest.mark.parametrize("profile", PROFILES)
@pytest.mark.parametrize("name", list(PARTS))
def test_every_written_mesh_reads_back_as_one_watertight_body(name, profile, part_files, tmp_path):
    settings = PARTS[name][1]
    config = small_config(sampler={"stride_mm": 8.0}, print={"profile": profile}, **settings)
    result = fcso.design([part_files[name]], config)
    if name in CARVED:
        assert result.best.case in ("good", "mixed"), (
            f"{name}, {profile}: the pad must be carved for the test to mean anything"
        )
    # the files exactly as fcso design writes them (pictures left out: they are not meshes)
    files = output_files(result, draw=lambda inputs, progress: collections.defaultdict(bytes))
    for file_name in ("finger.stl", "fingerpad.stl", "report.json"):
        (tmp_path / file_name).write_bytes(files[file_name])
    finger = _read_back(tmp_path / "finger.stl")
    _assert_one_body(finger, f"{name}, {profile}: finger.stl")
    _assert_one_body(_read_back(tmp_path / "fingerpad.stl"), f"{name}, {profile}: fingerpad.stl")
    report = json.loads((tmp_path / "report.json").read_text())
    # the report's figures are those of the file
    assert report["finger"]["watertight"] == finger.is_watertight
    assert report["finger"]["bodies"] == len(finger.split(only_watertight=False))
    assert report["finger"]["volume_mm3"] == pytest.approx(finger.volume, rel=1e-6)
    assert report["print_fit"]["profile"] == profile


def test_the_demo_parts_on_one_finger_write_one_body_without_the_float32_flap(tmp_path):
    # the batch demo's cube and solar tracker on one finger with its 10 mm pads: two vertices that
    # manifold3d keeps apart round to one float32 point and once left a two-triangle flap of zero volume beside the
    # finger, so the design was refused
    result = fcso.design(batch_demo_part_files(), batch_demo_settings().updated({"sampler": DEMO_10MM_PADS}))
    files = output_files(result, draw=lambda inputs, progress: collections.defaultdict(bytes))
    for file_name in ("finger.stl", "fingerpad.stl"):
        (tmp_path / file_name).write_bytes(files[file_name])
        _assert_one_body(_read_back(tmp_path / file_name), f"demo parts on one finger: {file_name}")


def test_a_zero_area_face_of_a_closed_surface_is_flipped_away():
    # a vertex that rounding to float32 put on the edge between two others: the face they make has no area, the
    # surface stays closed (one face of a 200-part job's 41-part set's pad, so the set's finger was refused)
    box = trimesh.creation.box(extents=(20.0, 10.0, 5.0))
    faces = [list(face) for face in box.faces]
    first = faces[0]
    a, c, x = first
    vertices = np.vstack([box.vertices, (box.vertices[a] + box.vertices[c]) / 2.0])
    b = len(vertices) - 1
    faces[0:1] = [[a, b, x], [b, c, x], [b, a, c]]
    needled = trimesh.Trimesh(vertices, faces, process=False)
    assert needled.is_watertight and (needled.area_faces < MIN_FACE_AREA_MM2).sum() == 1
    mended = without_zero_area_faces(needled)
    assert mended.is_watertight and mended.is_winding_consistent
    assert (mended.area_faces < MIN_FACE_AREA_MM2).sum() == 0
    assert mended.volume == pytest.approx(20.0 * 10.0 * 5.0)
    assert len(mended.faces) == len(needled.faces)
    # a mesh without such a face is returned as it is
    assert without_zero_area_faces(box) is box


def test_the_two_ridge_block_gets_a_written_finger_with_the_defaults(tmp_path):
    # its fused finger has a pinch, two sheets touching along an edge with distinct vertices at one position:
    # merged when the STL was read, they made edges of four faces and the design failed
    part = tmp_path / "two_ridge_block.stl"
    two_ridge_block().export(part)
    run = subprocess.run(
        [sys.executable, "-m", "fcso.cli", "design", str(part), "--poses", "1", "--out", str(tmp_path / "out")],
        capture_output=True,
        text=True,
        timeout=HANG_GUARD_S,
    )
    assert run.returncode == 0, run.stderr
    _assert_one_body(_read_back(tmp_path / "out" / "finger.stl"), "two_ridge_block finger.stl")


def test_a_gear_whose_finger_has_a_fan_of_vertices_closer_than_float32_is_written_as_one_body(tmp_path):
    # a spur gear of the test split (examples/part_families.py), the defaults: its pocket's floor meets a drafted wall
    # in a fan of six vertices within 7e-7 mm, which float32 keeps distinct; their faces have no area and no edge flip
    # mends a fan whose edges have no length, so the design was refused
    drawn = draw("spur-gear", 100)
    result = fcso.design([fcso.Part(name=drawn.name, path=drawn.name, mesh=drawn.mesh)], fcso.DesignConfig())
    files = output_files(result, draw=lambda inputs, progress: collections.defaultdict(bytes))
    for file_name in ("finger.stl", "fingerpad.stl"):
        (tmp_path / file_name).write_bytes(files[file_name])
        _assert_one_body(_read_back(tmp_path / file_name), f"spur gear 100: {file_name}")
