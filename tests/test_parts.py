"""Part loading: formats, units, scaling, refusal of bad meshes and explicit repair."""

import numpy as np
import pytest
import trimesh

from fcso import MeshError, load_part
from fcso.parts import unit_factor

from .conftest import data_path


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
    assert part.mesh.volume == pytest.approx(original.volume, rel=1e-6)


def test_open_mesh_is_refused_with_file_and_defect():
    with pytest.raises(MeshError) as error:
        load_part(data_path("encoder.stl"))
    assert "encoder.stl" in str(error.value) and "not watertight" in str(error.value)


def test_repair_when_asked_says_what_it_changed():
    part = load_part(data_path("encoder.stl"), repair=True)
    assert part.mesh.is_watertight and part.mesh.volume > 0
    assert part.repairs and any("removed" in change for change in part.repairs)


def test_hande_visual_finger_stays_open_even_after_repair():
    with pytest.raises(MeshError) as error:
        load_part(data_path("robotiq_hande_finger_visual.dae"), units="m", repair=True)
    assert "robotiq_hande_finger_visual.dae" in str(error.value) and "even after --repair" in str(error.value)


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
    assert "flipped inside-out mesh" in repaired.repairs


def test_unknown_unit_and_missing_file(tmp_path):
    with pytest.raises(MeshError, match="unknown unit"):
        unit_factor("furlong", "x.stl")
    with pytest.raises(MeshError, match="file not found"):
        load_part(tmp_path / "missing.stl")
    text = tmp_path / "part.txt"
    text.write_text("not a mesh")
    with pytest.raises(MeshError, match="unsupported file type"):
        load_part(text)
