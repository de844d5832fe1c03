"""Part loading: formats, units, scaling, refusal of bad meshes and explicit repair."""

import numpy as np
import pytest
import trimesh

from fcso import MeshError, load_part, load_parts
from fcso.geometry import box, to_manifold, to_trimesh
from fcso.parts import unit_factor
from tests.conftest import data_path


def test_stl_ply_in_mm_keep_their_size():
    cube = load_part(data_path("20mm-xyz-cube.stl"))
    assert np.allclose(cube.mesh.extents, 20.0, atol=1e-3)
    assert cube.mesh.is_watertight and cube.mesh.volume > 0
    bunny = load_part(data_path("stanford_bunny_closed.ply"))
    assert bunny.mesh.extents.max() < 1.0


def test_inch_part_is_scaled_by_25_4():
    raw = trimesh.load(data_path("angle_block.STL"))
    part = load_part(data_path("angle_block.STL"), units="inch")
    assert np.allclose(part.mesh.extents, raw.extents * 25.4, rtol=1e-9)
    assert part.scale == 25.4
    factor = load_part(data_path("angle_block.STL"), units=10.0)
    assert np.allclose(factor.mesh.extents, raw.extents * 10.0, rtol=1e-9)


def test_scale_to_longest_side():
    part = load_part(data_path("stanford_bunny_closed.ply"), scale_to_mm=65.0)
    assert part.mesh.extents.max() == pytest.approx(65.0, rel=1e-9)


@pytest.mark.parametrize("suffix", [".obj", ".3mf", ".ply"])
def test_other_formats_load_the_same_solid(tmp_path, suffix):
    original = trimesh.load(data_path("solar_tracker.stl"))
    path = tmp_path / f"solar{suffix}"
    original.export(path)
    part = load_part(path)
    # the four overlapping shells united, as from the STL
    assert part.mesh.volume == pytest.approx(10_629.0, rel=0.01)
    assert part.shells == 4


def test_open_mesh_is_refused_with_file_and_defect():
    with pytest.raises(MeshError) as error:
        load_part(data_path("encoder.stl"))
    assert "encoder.stl" in str(error.value) and "not watertight" in str(error.value)


def test_repair_when_asked_says_what_it_changed():
    part = load_part(data_path("encoder.stl"), repair=True)
    assert part.mesh.is_watertight and part.mesh.volume > 0
    assert part.repairs and any("removed" in change for change in part.repairs)


def test_hande_visual_finger_is_closed_by_repair():
    # four shells, one with a one-triangle hole: MeshFix closes it, manifold3d unites the shells
    raw = trimesh.load(str(data_path("robotiq_hande_finger_visual.dae")), force="mesh", process=False)
    raw_volume_mm3 = abs(raw.volume) * 1e9
    part = load_part(data_path("robotiq_hande_finger_visual.dae"), units="m", repair=True)
    assert part.mesh.is_watertight and len(part.mesh.split(only_watertight=False)) == 1
    assert part.repair.holes_filled == 1 and part.shells == 4
    # the shells overlap a little: their union is at most the sum, and within 1 % of it
    assert 0.99 * raw_volume_mm3 < part.mesh.volume <= raw_volume_mm3


def test_truncated_stl(tmp_path):
    path = tmp_path / "cut.stl"
    path.write_bytes(data_path("20mm-xyz-cube.stl").read_bytes()[:3000])
    with pytest.raises(MeshError, match="truncated binary STL"):
        load_part(path)


def test_empty_and_non_finite_meshes(tmp_path):
    empty = tmp_path / "empty.stl"
    empty.write_bytes(b"\0" * 80 + (0).to_bytes(4, "little"))
    with pytest.raises(MeshError, match="empty mesh"):
        load_part(empty)
    mesh = trimesh.load(data_path("20mm-xyz-cube.stl"))
    vertices = mesh.vertices.copy()
    vertices[3] = np.nan
    broken = tmp_path / "nan.ply"
    trimesh.Trimesh(vertices, mesh.faces, process=False).export(broken)
    with pytest.raises(MeshError, match="non-finite"):
        load_part(broken)


def test_zero_volume_and_inside_out(tmp_path):
    mesh = trimesh.load(data_path("20mm-xyz-cube.stl"))
    flat = mesh.copy()
    flat.vertices[:, 2] = 0.0
    flat_path = tmp_path / "flat.ply"
    flat.export(flat_path)
    with pytest.raises(MeshError):
        load_part(flat_path)
    inverted = trimesh.Trimesh(mesh.vertices, mesh.faces[:, ::-1], process=False)
    inverted_path = tmp_path / "inverted.ply"
    inverted.export(inverted_path)
    with pytest.raises(MeshError, match="inside-out"):
        load_part(inverted_path)
    repaired = load_part(inverted_path, repair=True)
    assert repaired.mesh.volume == pytest.approx(mesh.volume, rel=1e-9)
    assert repaired.repair.shells_inverted == 1 and "turned 1 inside-out shells outward" in repaired.repairs


def test_unknown_unit_and_missing_file(tmp_path):
    with pytest.raises(MeshError, match="unknown unit"):
        unit_factor("furlong", "x.stl")
    with pytest.raises(MeshError, match="file not found"):
        load_part(tmp_path / "missing.stl")
    text = tmp_path / "part.txt"
    text.write_text("not a mesh")
    with pytest.raises(MeshError, match="unsupported file type"):
        load_part(text)


# ---------------------------------------------------------------- shells and solids
# Figures from the fixtures' own shells (tests/data/README.md): solar_tracker.stl's
# four shells add up to 11 745 mm³ and their union is 10 629 mm³.


def test_overlapping_shells_are_one_solid():
    part = load_part(data_path("solar_tracker.stl"))
    raw = trimesh.load(data_path("solar_tracker.stl"))
    assert raw.volume == pytest.approx(11_745.0, rel=0.001)
    assert part.mesh.volume == pytest.approx(10_629.0, rel=0.01)
    assert part.mesh.is_watertight and part.shells == 4 and part.solid_index is None
    assert "4 overlapping or touching shells united" in part.shell_note
    assert part.warnings == []
    plug = load_part(data_path("capsela200_plug.stl"))
    assert plug.shells == 2 and plug.mesh.volume < trimesh.load(data_path("capsela200_plug.stl")).volume - 100.0


def test_touching_shells_are_one_solid():
    parts = load_parts(data_path("box.STL"))
    assert len(parts) == 1
    assert parts[0].shells == 10 and parts[0].mesh.is_watertight
    assert len(parts[0].mesh.split(only_watertight=False)) == 1


def test_separate_solids_are_separate_parts_largest_first():
    parts = load_parts(data_path("DC-DC_case.stl"))
    assert [p.name for p in parts] == ["DC-DC_case#1", "DC-DC_case#2"]
    assert [p.solid_index for p in parts] == [1, 2]
    assert parts[0].mesh.volume > parts[1].mesh.volume > 0
    assert all(p.mesh.is_watertight for p in parts)
    assert any("DC-DC_case.stl holds 2 separate solids" in w for w in parts[0].warnings)
    # the two solids do not overlap
    assert (to_manifold(parts[0].mesh) ^ to_manifold(parts[1].mesh)).volume() == pytest.approx(0.0, abs=1e-6)


def test_separate_solids_refused_without_splitting():
    with pytest.raises(MeshError, match=r"DC-DC_case.stl: holds 2 separate solids"):
        load_parts(data_path("DC-DC_case.stl"), split_bodies=False)
    with pytest.raises(MeshError, match=r"DC-DC_case.stl: holds 2 parts"):
        load_part(data_path("DC-DC_case.stl"))


def test_void_and_the_piece_inside_it_stay_with_their_solid(tmp_path):
    hollow = box((0, 0, 0), (20, 20, 20)) - box((5, 5, 5), (15, 15, 15))
    inside = box((8, 8, 8), (12, 12, 12))
    apart = box((30, 0, 0), (40, 10, 10))
    overlapping = box((35, 5, 5), (45, 12, 12))
    path = tmp_path / "nested.stl"
    trimesh.util.concatenate([to_trimesh(m) for m in (hollow, inside, apart, overlapping)]).export(path)
    parts = load_parts(path)
    assert [p.name for p in parts] == ["nested#1", "nested#2"]
    # 20³ - 10³ + 4³ and 10³ + 10 x 7 x 7 - 5 x 5 x 5
    assert parts[0].mesh.volume == pytest.approx(8000 - 1000 + 64, abs=1e-3)
    assert parts[1].mesh.volume == pytest.approx(1000 + 490 - 125, abs=1e-3)
    assert parts[0].shells == 3 and parts[1].shells == 2


def test_3mf_build_gives_one_part_per_object(tmp_path):
    scene = trimesh.Scene()
    cube = load_part(data_path("20mm-xyz-cube.stl")).mesh
    plug = load_part(data_path("capsela200_plug.stl")).mesh
    scene.add_geometry(cube, node_name="cube_a", transform=trimesh.transformations.translation_matrix([0, 0, 0]))
    scene.add_geometry(cube, node_name="cube_b", transform=trimesh.transformations.translation_matrix([40, 0, 0]))
    scene.add_geometry(plug, node_name="plug", transform=trimesh.transformations.translation_matrix([0, 60, 0]))
    path = tmp_path / "build.3mf"
    scene.export(path)
    parts = load_parts(path)
    assert len(parts) == 2
    volumes = sorted(p.mesh.volume for p in parts)
    assert volumes == pytest.approx(sorted([cube.volume, plug.volume]), rel=1e-4)
    by_count = sorted(len(p.instances) for p in parts)
    assert by_count == [1, 2]
    assert all(name.startswith("build/") for name in (p.name for p in parts))
