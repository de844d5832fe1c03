"""Pad geometries, the good/bad filter, the three fingerpad cases and seating (METHOD §4-6)."""

import numpy as np
import pytest
import trimesh

from fcso import load_part
from fcso.config import FilterConfig, SamplerConfig
from fcso.contact import sample_surface, seat
from fcso.geometry import box, to_manifold, to_trimesh
from fcso.pad import build_fingerpad, pad_geometry
from fcso.sampler import GraspSample
from tests.conftest import data_path

SAMPLER = SamplerConfig(length_mm=10.0, width_mm=10.0, thickness_mm=4.0, penetration_mm=3.0)
FILTER = FilterConfig()


def xyz_cube() -> trimesh.Trimesh:
    """The 20 mm calibration cube (letters engraved 0.5 mm deep), centred in x-y, on the table."""
    mesh = load_part(data_path("20mm-xyz-cube.stl")).mesh
    lower, upper = mesh.bounds
    mesh.apply_translation([-(lower[0] + upper[0]) / 2, -(lower[1] + upper[1]) / 2, -lower[2]])
    return mesh


def engraving_depth(mesh: trimesh.Trimesh) -> float:
    """Depth of the letter on the +x face, from the mesh itself."""
    facing = (mesh.face_normals[:, 0] > 0.999) & (mesh.triangles_center[:, 0] > 5.0)
    x = mesh.triangles_center[facing, 0]
    return float(x.max() - x.min())


def grooved(mesh: trimesh.Trimesh, sides=(1,), depth=2.0, width=4.0) -> trimesh.Trimesh:
    """Cut a full-height groove ``depth`` deep and ``width`` wide into the ±x faces (manifold3d)."""
    solid = to_manifold(mesh)
    for side in sides:
        x0, x1 = (10.0 - depth, 11.0) if side > 0 else (-11.0, -10.0 + depth)
        solid = solid - box((x0, -width / 2, -1.0), (x1, width / 2, 21.0))
    return to_trimesh(solid)


def geometry(mesh, sample, side, sampler=SAMPLER):
    return pad_geometry(to_manifold(mesh), mesh.vertices, mesh.faces, sample.pad_frame(side, sampler), sampler, FILTER)


def centred_sample(a_max=10.0, a_min=-10.0, h=5.0):
    return GraspSample(
        yaw_deg=0.0, s_mm=0.0, h_mm=h, a_max_mm=a_max, a_min_mm=a_min, area_plus_mm2=0.0, area_minus_mm2=0.0
    )


def test_pad_frames_are_rotations_facing_each_other():
    sample = centred_sample()
    plus, minus = sample.pad_frame(1, SAMPLER), sample.pad_frame(-1, SAMPLER)
    for frame in (plus, minus):
        assert np.allclose(frame[:3, :3] @ frame[:3, :3].T, np.eye(3)) and np.linalg.det(
            frame[:3, :3]
        ) == pytest.approx(1.0)
    # the part's outermost points lie at u = D in both frames
    assert trimesh.transform_points([[10.0, 0.0, 5.0]], plus)[0] == pytest.approx([3.0, 5.0, 0.0])
    assert trimesh.transform_points([[-10.0, 0.0, 5.0]], minus)[0] == pytest.approx([3.0, 5.0, 0.0])
    # the "-" frame is the "+" frame turned 180 degrees about z
    assert np.allclose(minus[:3, :3], np.diag([-1.0, -1.0, 1.0]) @ plus[:3, :3])


def test_flat_face_with_shallow_engraving_is_bad():
    cube = xyz_cube()
    result = geometry(cube, centred_sample(), 1)
    assert not result.good and result.basis == "ratio"
    assert result.ratio < FILTER.volume_ratio_threshold
    assert result.depth_mm == pytest.approx(engraving_depth(cube), abs=0.01)


def test_concave_groove_is_good_by_ratio():
    result = geometry(grooved(xyz_cube()), centred_sample(), 1)
    assert result.good and result.basis == "ratio"
    assert result.depth_mm == pytest.approx(2.0, abs=0.01)
    # the groove alone empties 4 x 2 x 10 of the 10 x 3 x 10 box
    assert result.ratio >= 80.0 / 300.0 - 1e-6


def test_tilted_edge_is_judged_by_its_normals():
    cube = xyz_cube()
    cube.apply_transform(trimesh.transformations.rotation_matrix(np.radians(45.0), [0, 0, 1]))
    reach = float(cube.vertices[:, 0].max())
    result = geometry(cube, centred_sample(a_max=reach, a_min=-reach), 1)
    assert result.depth_mm == pytest.approx(SAMPLER.penetration_mm)
    assert result.basis == "normals" and result.good
    assert abs(result.dominant_normal[0]) == pytest.approx(np.cos(np.radians(45.0)), abs=0.02)


def test_flat_face_covering_part_of_the_pad_is_bad_by_normals():
    # pad from z = 15 to 25 on a 20 mm cube: the face covers half of it
    result = geometry(xyz_cube(), centred_sample(h=15.0), 1)
    assert result.depth_mm == pytest.approx(SAMPLER.penetration_mm)
    assert result.basis == "normals" and not result.good


def _slice_area(pad, u):
    turned = pad.transform([[0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [1.0, 0.0, 0.0, 0.0]])
    return turned.slice(u).area()


def test_only_bad_geometries_give_the_flat_pad():
    cube = xyz_cube()
    sample = centred_sample()
    pad = build_fingerpad([geometry(cube, sample, 1), geometry(cube, sample, -1)], SAMPLER, FILTER)
    assert pad.case == "bad"
    T, D, L, W = SAMPLER.thickness_mm, SAMPLER.penetration_mm, SAMPLER.length_mm, SAMPLER.width_mm
    assert pad.pad.volume() == pytest.approx((T - D) * L * W, rel=1e-6)
    assert np.allclose(pad.pad.bounding_box(), (D, 0.0, 0.0, T, L, W), atol=1e-5)


def test_only_good_geometries_carve_the_tongue():
    part = grooved(xyz_cube(), sides=(1, -1))
    sample = centred_sample()
    geometries = [geometry(part, sample, 1), geometry(part, sample, -1)]
    assert all(g.good for g in geometries)
    pad = build_fingerpad(geometries, SAMPLER, FILTER)
    assert pad.case == "good" and pad.block_depth_mm is None
    assert _slice_area(pad.pad, 0.5) == pytest.approx(0.0, abs=1e-6)
    assert _slice_area(pad.pad, 1.5) == pytest.approx(4.0 * 10.0, rel=1e-3)
    assert _slice_area(pad.pad, 3.5) == pytest.approx(10.0 * 10.0, rel=1e-6)


def _seat(part, sample, side, pad, sampler=SAMPLER):
    g = geometry(part, sample, side, sampler)
    surface = sample_surface(g.surface_vertices, g.surface_faces, 4.0, seed=[0, 1 + side])
    mesh = to_trimesh(pad.pad)
    return seat([surface], mesh.vertices, mesh.faces, 0.05)[0]


def test_mixed_pad_and_seating_offsets():
    sampler = SamplerConfig(length_mm=10.0, width_mm=10.0, thickness_mm=4.5, penetration_mm=3.5)
    part = grooved(xyz_cube(), sides=(1,))
    sample = centred_sample()
    good = geometry(part, sample, 1, sampler)
    bad = geometry(part, sample, -1, sampler)
    assert good.good and not bad.good
    pad = build_fingerpad([good, bad], sampler, FILTER)
    assert pad.case == "mixed"
    assert pad.block_depth_mm == pytest.approx(FILTER.block_factor * 2.0, abs=0.02)
    # the block [0, D - d_B] lies inside the groove's full-cover slab: the pad is the tongue
    assert _slice_area(pad.pad, 1.0) == pytest.approx(0.0, abs=1e-6)
    assert _slice_area(pad.pad, 2.5) == pytest.approx(4.0 * 10.0, rel=1e-3)
    # the grooved side sits in its own carving; the flat side must back off the tongue
    assert _seat(part, sample, 1, pad, sampler).offset_mm == 0.0
    flat = _seat(part, sample, -1, pad, sampler)
    assert flat.offset_mm == pytest.approx(2.0 - 0.05, abs=0.02)


def test_flat_pad_seats_at_zero_with_the_face_in_contact():
    cube = xyz_cube()
    sample = centred_sample()
    pad = build_fingerpad([geometry(cube, sample, 1), geometry(cube, sample, -1)], SAMPLER, FILTER)
    contact = _seat(cube, sample, 1, pad)
    assert contact.offset_mm == 0.0
    # expected: the +x face triangles at x = 10 inside the footprint (engraving excluded)
    local = cube.copy()
    local.apply_transform(sample.pad_frame(1, SAMPLER))
    vertices, faces = local.vertices, local.faces
    for normal, origin in (
        ((0, 1, 0), (0, 0, 0)),
        ((0, -1, 0), (0, 10, 0)),
        ((0, 0, 1), (0, 0, 0)),
        ((0, 0, -1), (0, 0, 10)),
    ):
        vertices, faces = trimesh.intersections.slice_faces_plane(
            vertices, faces, np.array(normal, float), np.array(origin, float)
        )[:2]
    local = trimesh.Trimesh(vertices, faces, process=False)
    on_face = np.abs(local.triangles_center[:, 0] - SAMPLER.penetration_mm) < 1e-6
    expected = float(local.area_faces[on_face].sum())
    assert 50.0 < expected < 100.0
    assert contact.contact_area_mm2 == pytest.approx(expected, rel=0.06)
