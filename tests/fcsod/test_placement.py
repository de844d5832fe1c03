"""Build placement: reading builds, placing the fingers, writing build.3mf.

Every placed build is checked here without the placer's code: bounds from the
transformed meshes, pairwise gaps with manifold3d's exact ``min_gap``.
"""

from __future__ import annotations

import io
import itertools
import zipfile
from pathlib import Path

import manifold3d
import numpy as np
import pytest
import trimesh
from pydantic import ValidationError

from fcso.config import DesignConfig
from fcso.errors import MeshError
from fcso.finger import parametric_finger
from fcso.threemf import check_zip_archive
from fcsod.plate.build3mf import (
    Build,
    BuildItem,
    export_build_3mf,
    parse_transform,
    read_build,
    read_build_3mf,
    write_build_3mf,
)
from fcsod.plate.models import BuildConfig, PlacementReport
from fcsod.plate.placement import place_fingers

DATA = Path(__file__).parents[1] / "data"
INCH_MM = 25.4


def load(name: str, scale: float = 1.0) -> trimesh.Trimesh:
    mesh = trimesh.load(DATA / name, force="mesh")
    mesh.apply_scale(scale)
    return mesh


def at(mesh: trimesh.Trimesh, corner, rotation=None) -> np.ndarray:
    """Transform that (optionally rotates and) puts the mesh's bounding-box corner at ``corner``."""
    transform = np.eye(4)
    if rotation is not None:
        transform[:3, :3] = rotation
    lower = (mesh.vertices @ transform[:3, :3].T).min(axis=0)
    transform[:3, 3] = np.asarray(corner, dtype=float) - lower
    return transform


def exact_gap(a: trimesh.Trimesh, b: trimesh.Trimesh, search_mm: float) -> float:
    """Exact gap (capped at ``search_mm``) between two closed meshes; 0 when they overlap."""

    def solid(mesh):
        return manifold3d.Manifold(
            manifold3d.Mesh(
                vert_properties=np.asarray(mesh.vertices, dtype=np.float32),
                tri_verts=np.asarray(mesh.faces, dtype=np.uint32),
            )
        )

    return solid(a).min_gap(solid(b), search_mm)


def check_build(items, config: BuildConfig, expected_count: int) -> list[trimesh.Trimesh]:
    """Assert the placement rules on the placed meshes; return them."""
    assert len(items) == expected_count
    assert len({item.name for item in items}) == expected_count
    meshes = [item.mesh.copy().apply_transform(item.transform) for item in items]
    lower = np.asarray(config.origin_mm) + config.wall_margin_mm
    upper = np.asarray(config.origin_mm) + np.asarray(config.volume_mm) - config.wall_margin_mm
    for item, mesh in zip(items, meshes):
        assert np.all(mesh.bounds[0] >= lower - 1e-6), (item.name, mesh.bounds)
        assert np.all(mesh.bounds[1] <= upper + 1e-6), (item.name, mesh.bounds)
    for (i, a), (j, b) in itertools.combinations(enumerate(meshes), 2):
        box_gap = np.linalg.norm(np.maximum(0.0, np.maximum(a.bounds[0] - b.bounds[1], b.bounds[0] - a.bounds[1])))
        if box_gap >= config.spacing_mm:
            continue
        gap = exact_gap(a, b, config.spacing_mm + 1.0)
        assert gap >= config.spacing_mm - 1e-6, (items[i].name, items[j].name, gap)
    return meshes


@pytest.fixture(scope="module")
def finger() -> trimesh.Trimesh:
    config = DesignConfig().updated({"sampler": {"length_mm": 20.0}})
    return parametric_finger(config.sampler, config.gripper).mesh


@pytest.fixture(scope="module")
def plate() -> trimesh.Trimesh:
    return load("plate_holes.STL")


def dense_build(plate: trimesh.Trimesh) -> Build:
    """The plate (turned to 305 x 203) covering the floor of a 325 x 225 volume."""
    turn = trimesh.transformations.rotation_matrix(np.pi / 2, [0, 0, 1])[:3, :3]
    return Build(items=[BuildItem("plate", plate, at(plate, (5.0, 5.0, 5.0), turn))])


DENSE_CONFIG = dict(volume_mm=(325.0, 225.0, 150.0), spacing_mm=3.0, wall_margin_mm=5.0)


def test_sparse_build_fingers_go_to_the_floor_pad_up(finger):
    config = BuildConfig()
    parts = {
        "cube": (load("20mm-xyz-cube.stl"), (40, 40, 10)),
        "dc_case": (load("DC-DC_case.stl"), (90, 40, 10)),
        "plug": (load("capsela200_plug.stl"), (40, 120, 10)),
        "tracker": (load("solar_tracker.stl"), (250, 180, 10)),
        "riser": (load("idler_riser.STL", INCH_MM), (260, 40, 10)),
    }
    build = Build(items=[BuildItem(name, mesh, at(mesh, corner)) for name, (mesh, corner) in parts.items()])
    parts_height = max(item.placed_mesh().bounds[1, 2] for item in build.items)

    result = place_fingers(build, finger, config)

    assert result.fingers_fit and result.report.all_items_placed
    assert result.report.mode == "add_fingers"
    meshes = check_build(result.items, config, len(parts) + 2)
    for item, mesh in zip(result.items, meshes):
        if item.kind == "part":
            np.testing.assert_allclose(item.transform, dict((i.name, i.transform) for i in build.items)[item.name])
            continue
        # on the floor (within one voxel of the wall margin), pad face up
        assert mesh.bounds[0, 2] < config.wall_margin_mm + config.voxel_mm
        np.testing.assert_allclose(item.transform[:3, :3] @ [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], atol=1e-9)
    assert result.report.build_height_mm == pytest.approx(parts_height, abs=1e-6)
    assert result.report.finger_copies_placed == 2 and result.report.extra_height_needed_mm is None
    assert 0.0 < result.report.packing_density < 1.0


def test_dense_build_fingers_go_above_the_parts(finger, plate):
    config = BuildConfig(**DENSE_CONFIG)
    build = dense_build(plate)
    parts_top = max(item.placed_mesh().bounds[1, 2] for item in build.items)

    result = place_fingers(build, finger, config)

    assert result.fingers_fit
    meshes = check_build(result.items, config, 3)
    finger_meshes = [mesh for item, mesh in zip(result.items, meshes) if item.kind == "finger"]
    assert len(finger_meshes) == 2
    for mesh in finger_meshes:
        assert mesh.bounds[0, 2] >= parts_top + config.spacing_mm - 1e-6
    assert result.report.build_height_mm > parts_top + config.spacing_mm
    # the report's nearest neighbours agree with an exact gap within its 0.1 mm
    by_name = {item.name: mesh for item, mesh in zip(result.items, meshes)}
    for entry in result.report.items:
        exact = exact_gap(by_name[entry.name], by_name[entry.nearest_item], 1e3)
        assert entry.nearest_distance_mm == pytest.approx(exact, abs=0.11)


def test_no_room_says_so_and_suggests_the_height(finger, plate):
    config = BuildConfig(**{**DENSE_CONFIG, "volume_mm": (325.0, 225.0, 40.0)})
    build = dense_build(plate)

    result = place_fingers(build, finger, config)

    report = result.report
    assert not result.fingers_fit and not report.all_items_placed
    assert report.finger_copies_placed == 0 and report.unplaced_items == ["finger-1", "finger-2"]
    assert "do not fit" in report.message and "more free build height" in report.message
    assert report.extra_height_needed_mm > 0
    # the parts are still a valid build, and build.3mf can still be written
    check_build(result.items, config, 1)
    assert len(export_build_3mf(result.items)) > 0
    # the suggested height is enough
    taller = config.model_copy(update={"volume_mm": (325.0, 225.0, 40.0 + report.extra_height_needed_mm)})
    retry = place_fingers(build, finger, taller)
    assert retry.fingers_fit
    check_build(retry.items, taller, 3)


def test_unplaced_batch_packs_parts_and_fingers(finger, tmp_path):
    config = BuildConfig()
    files = {
        "cube.stl": load("20mm-xyz-cube.stl"),
        "case.stl": load("DC-DC_case.stl"),
        "plug.stl": load("capsela200_plug.stl"),
        "tracker.stl": load("solar_tracker.stl"),
        "plate.stl": load("plate_holes.STL"),
        "bunny.ply": load("stanford_bunny_closed.ply", 65.0 / 0.843),
        "block.stl": load("angle_block.STL"),
        "riser.stl": load("idler_riser.STL"),
    }
    for name, mesh in files.items():
        mesh.export(tmp_path / name)
    units = {"block.stl": "inch", "riser.stl": "inch"}
    build = read_build(sorted(tmp_path.iterdir()), units=units)
    assert not build.placed and all(item.transform is None for item in build.items)

    result = place_fingers(build, finger, config)

    assert result.report.mode == "pack" and result.report.all_items_placed
    meshes = check_build(result.items, config, len(files) + 2)
    # the plate (305 mm long) only fits the 284 mm deep volume turned about z
    plate = next(mesh for item, mesh in zip(result.items, meshes) if item.name == "plate")
    assert plate.extents[0] > 300
    assert result.report.build_height_mm == pytest.approx(max(mesh.bounds[1, 2] for mesh in meshes))


def test_build_3mf_reloads_with_the_same_items_and_transforms(finger, plate, tmp_path):
    config = BuildConfig(**DENSE_CONFIG)
    result = place_fingers(dense_build(plate), finger, config)
    path = write_build_3mf(result.items, tmp_path / "build.3mf")

    scene = trimesh.load(path)
    assert isinstance(scene, trimesh.Scene)
    assert sorted(scene.graph.nodes_geometry) == sorted(item.name for item in result.items)
    for item in result.items:
        transform, geometry = scene.graph[item.name]
        np.testing.assert_array_equal(transform, item.transform)
        np.testing.assert_allclose(scene.geometry[geometry].vertices, item.mesh.vertices)
    assert export_build_3mf(result.items) == path.read_bytes()

    reread = read_build([path])
    assert reread.placed and len(reread.items) == len(result.items)
    by_name = {item.name: item for item in result.items}
    for item in reread.items:
        np.testing.assert_array_equal(item.transform, by_name[item.name.split("/", 1)[1]].transform)


def test_placed_3mf_build_gets_the_fingers(finger, tmp_path):
    cube, plug = load("20mm-xyz-cube.stl"), load("capsela200_plug.stl")
    turn = trimesh.transformations.rotation_matrix(np.pi / 2, [0, 0, 1])[:3, :3]
    parts = [BuildItem("cube", cube, at(cube, (100, 100, 10))), BuildItem("plug", plug, at(plug, (150, 60, 10), turn))]
    path = write_build_3mf(parts, tmp_path / "job.3mf")

    build = read_build([path])
    result = place_fingers(build, finger, BuildConfig())

    assert build.placed and result.fingers_fit
    check_build(result.items, BuildConfig(), 4)
    np.testing.assert_allclose(result.items[1].placed_mesh().bounds, parts[1].placed_mesh().bounds)


def test_loose_meshes_with_manifest_transforms(tmp_path):
    cube = load("20mm-xyz-cube.stl")
    for name in ("a.stl", "b.stl", "c.stl"):
        cube.export(tmp_path / name)
    moved = at(cube, (50, 60, 10))
    build = read_build(
        sorted(tmp_path.glob("*.stl")),
        transforms={"a.stl": moved.reshape(-1).tolist(), "b": moved.tolist()},
        units={"c.stl": "inch"},
    )
    assert [item.name for item in build.items] == ["a", "b", "c"]
    np.testing.assert_allclose(build.items[0].transform, moved)
    np.testing.assert_allclose(build.items[1].transform, moved)
    assert build.items[2].transform is None and not build.placed
    np.testing.assert_allclose(build.items[2].mesh.extents, cube.extents * INCH_MM, rtol=1e-6)


@pytest.mark.parametrize(
    "value, defect",
    [
        ([1, 2, 3], "16 numbers"),
        (np.eye(4)[:3].tolist(), "16 numbers"),
        ([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]], "last row"),
        (np.diag([1.0, 1.0, 0.0, 1.0]).tolist(), "singular"),
        ([float("nan")] * 16, "non-finite"),
    ],
)
def test_bad_manifest_transform_is_refused(value, defect):
    with pytest.raises(MeshError, match=defect):
        parse_transform(value, "part.stl: transform")


def test_zip_bomb_is_refused_before_reading(tmp_path):
    bomb = tmp_path / "bomb.3mf"
    with zipfile.ZipFile(bomb, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("3D/3dmodel.model", b"\0" * (20 << 20))
    with pytest.raises(MeshError, match="zip bomb"):
        check_zip_archive(bomb)
    with pytest.raises(MeshError, match="zip bomb"):
        read_build_3mf(bomb)
    small = tmp_path / "small.3mf"
    small.write_bytes(export_build_3mf([BuildItem("cube", load("20mm-xyz-cube.stl"), np.eye(4))]))
    with pytest.raises(MeshError, match="inflates"):
        check_zip_archive(small, max_uncompressed_bytes=100)
    not_zip = tmp_path / "broken.3mf"
    not_zip.write_bytes(b"not a zip")
    with pytest.raises(MeshError, match="zip"):
        read_build([not_zip])


def test_build_config_section_names_and_limits():
    config = BuildConfig.model_validate(
        {"volume_mm": [200, 200, 100], "spacing_mm": 4, "wall_margin_mm": 8, "finger_copies": 3}
    )
    assert config.volume_mm == (200.0, 200.0, 100.0) and config.finger_copies == 3
    assert BuildConfig().volume_mm == (380.0, 284.0, 380.0) and BuildConfig().finger_copies == 2
    with pytest.raises(ValidationError):
        BuildConfig(volume_mm=(100, 100, 100), wall_margin_mm=50)
    with pytest.raises(ValidationError):
        BuildConfig(spacing_mm=-1)
    with pytest.raises(ValidationError):
        BuildConfig(volume_mm_typo=(1, 2, 3))
    schema = PlacementReport.model_json_schema()
    assert {"build_height_mm", "packing_density", "items", "extra_height_needed_mm"} <= set(schema["properties"])


def test_spare_fingers_are_placed_when_there_is_room(finger):
    config = BuildConfig(finger_copies=2, spare_fingers=1, finger_orientations="pad_up")
    cube = load("20mm-xyz-cube.stl")
    result = place_fingers(Build([BuildItem("cube", cube, at(cube, (100, 100, 10)))]), finger, config)
    assert result.report.finger_copies_placed == 3 and result.fingers_fit
    meshes = check_build(result.items, config, 4)
    for item in result.items[1:]:
        np.testing.assert_allclose(item.transform[:3, :3] @ [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], atol=1e-9)
    assert io.BytesIO(export_build_3mf(result.items)).getbuffer().nbytes > 0
    assert len(meshes) == 4


def test_surface_voxels_hold_every_surface_point():
    """The voxeliser is a superset of the voxels the surface touches, thin and slanted triangles included."""
    from fcsod.plate.voxels import surface_voxels

    sliver = trimesh.Trimesh(
        vertices=[[0.3, 0.2, 0.1], [97.1, 40.3, 13.7], [97.4, 40.9, 13.2], [50.0, 20.0, 60.0]],
        faces=[[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]],
    )
    slanted = trimesh.creation.box(extents=(40.0, 25.0, 10.0))
    slanted.apply_transform(trimesh.transformations.rotation_matrix(0.7, [1.0, 2.0, 3.0]))
    for mesh in (sliver, slanted, load("stanford_bunny_closed.ply")):
        voxel = 2.0
        origin = mesh.bounds[0] - 2.0 * voxel
        shape = np.ceil(mesh.extents / voxel).astype(int) + 4
        grid = surface_voxels(mesh.vertices, mesh.faces, origin, voxel, shape)
        points, _ = trimesh.sample.sample_surface(mesh, 50000, seed=0)
        points = np.concatenate([points, mesh.vertices])
        assert grid[tuple(np.floor((points - origin) / voxel).astype(int).T)].all()
        # cells span at most a voxel per axis: the surface layer stays thin
        assert grid.sum() < 3.0 * mesh.area / voxel**2 + 200
