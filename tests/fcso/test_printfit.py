"""Printed fit: clearance, lead-ins, thin walls and printer profiles, with real manifold3d Booleans on real meshes."""

from __future__ import annotations

import dataclasses

import igl
import manifold3d
import numpy as np
import pytest
import trimesh

import fcso
from fcso.config import DesignConfig, PrintConfig, load_config
from fcso.contact import sample_surface
from fcso.errors import ConfigError
from fcso.finger import finger_plate, fuse, parametric_finger
from fcso.geometry import affine_3x4, box, to_manifold
from fcso.output.design_page import rebuild_report
from fcso.pad import build_fingerpad, pad_box, pad_geometry, surface_in_pad
from fcso.poses import stable_poses
from fcso.printfit import (
    CONE_SEGMENTS,
    ball_points,
    carve,
    cone_points,
    minkowski_convex,
    minkowski_difference_convex,
    open_thin_walls,
    thinnest_wall_mm,
)
from fcso.report.models import DesignReport
from fcso.sampler import SIDES, sample_grasps
from fcsod.config import parse_manifest
from tests.conftest import data_path, small_config

#: small_config's pad box (T, L, W), mm.
SIZE = (4.0, 10.0, 10.0)
#: Fixture parts the geometry tests carve pockets for (tests/data/README.md).
FIXTURE_PARTS = {"angle_block.STL": 25.4, "DC-DC_case.stl": 1.0, "solar_tracker.stl": 1.0}


def _good_geometries(name: str, config: DesignConfig, limit: int = 4):
    """Real pad geometries of a fixture part: (rest-frame mesh, pad frame) of good samples, most probable pose."""
    part = fcso.load_parts(data_path(name))[0]
    mesh = part.mesh.copy()
    mesh.apply_scale(FIXTURE_PARTS[name])
    transforms, _ = stable_poses(mesh)
    mesh.apply_transform(transforms[0])
    plate = finger_plate(parametric_finger(config.sampler, config.gripper), config.sampler, config.gripper)
    manifold = to_manifold(mesh)
    found = []
    for sample in sample_grasps(mesh, config.sampler, config.gripper, plate).samples:
        for side in SIDES:
            frame = sample.pad_frame(side, config.sampler)
            exact = pad_geometry(manifold, mesh.vertices, mesh.faces, frame, config.sampler, config.filter)
            if exact.good:
                found.append((mesh, manifold, frame))
                break
        if len(found) == limit:
            break
    assert found, f"{name}: no good pad geometry to carve"
    return found


def _signed_distance(points: np.ndarray, mesh: trimesh.Trimesh) -> np.ndarray:
    return igl.signed_distance(
        np.ascontiguousarray(points, dtype=np.float64),
        np.ascontiguousarray(mesh.vertices, dtype=np.float64),
        np.ascontiguousarray(mesh.faces, dtype=np.int64),
    )[0]


@pytest.mark.parametrize("name", sorted(FIXTURE_PARTS))
def test_a_drafted_pocket_keeps_c_sin_alpha_from_the_part_and_seats_it_c_deeper(name):
    # METHOD §9c: the clearance becomes depth. At its designed depth the part is at least c sin(lead-in) from the
    # printed pocket everywhere (a pocket printed that much smaller still takes it); moved c deeper it touches the
    # pocket's drafted walls, which centre it, and still does not enter the pad
    clearance, angle = 0.4, 15.0
    config = small_config(print={"clearance_mm": clearance, "lead_in_deg": angle, "min_wall_mm": 0.5})
    sampler = config.sampler
    for mesh, manifold, frame in _good_geometries(name, config, limit=1):
        exact = pad_geometry(manifold, mesh.vertices, mesh.faces, frame, sampler, config.filter)
        carved = carve(manifold, frame, SIZE, sampler.penetration_mm, clearance, angle)
        geometry = dataclasses.replace(exact, intersection=carved)
        pad = build_fingerpad([geometry], sampler, config.filter).pad
        pad = open_thin_walls(pad, sampler.thickness_mm, sampler.length_mm, sampler.width_mm, 0.5)
        pad_mesh = trimesh.Trimesh(*_arrays(pad), process=False)
        surface = surface_in_pad(mesh.vertices, mesh.faces, frame, sampler)
        points = sample_surface(*surface, density_per_mm2=20.0, seed=1).points
        assert len(points) > 100
        designed = _signed_distance(points, pad_mesh)
        assert designed.min() >= clearance * np.sin(np.radians(angle)) - 0.02, (name, float(designed.min()))
        seated = _signed_distance(points + [clearance, 0.0, 0.0], pad_mesh)
        assert -0.02 <= seated.min() < 0.02, (name, float(seated.min()))


@pytest.mark.parametrize("profile", ["mjf-pa12", "fdm-pla", "sla-resin"])
def test_every_profile_carves_one_watertight_finger_for_each_fixture_part(profile):
    # solar_tracker and capsela200_plug go through the whole design in the test below
    config = small_config(print={"profile": profile})
    fit = config.print.resolved()
    sampler = config.sampler
    finger = parametric_finger(sampler, config.gripper)
    for name in ("angle_block.STL", "DC-DC_case.stl"):
        for mesh, manifold, frame in _good_geometries(name, config, limit=2):
            exact = pad_geometry(manifold, mesh.vertices, mesh.faces, frame, sampler, config.filter)
            carved = carve(manifold, frame, SIZE, sampler.penetration_mm, fit["clearance_mm"], fit["lead_in_deg"])
            pad = build_fingerpad([dataclasses.replace(exact, intersection=carved)], sampler, config.filter).pad
            pad = open_thin_walls(pad, *SIZE, fit["min_wall_mm"])
            fused = fuse(finger, pad, sampler, config.finger.overlap_mm)
            assert fused.bodies == 1 and fused.mesh.is_watertight and fused.volume_mm3 > 0, (profile, name)


def _arrays(manifold: manifold3d.Manifold):
    mesh = manifold.to_mesh()
    return np.asarray(mesh.vert_properties[:, :3], dtype=np.float64), np.asarray(mesh.tri_verts, dtype=np.int64)


def _peg_part(pegs) -> trimesh.Trimesh:
    """A slab behind the pad face (u < 0) carrying box pegs that reach into the pad; built in the pad frame."""
    slab = box((-8.0, -5.0, -5.0), (-0.5, 15.0, 15.0))
    solid = manifold3d.Manifold.batch_boolean([slab, *[box(lo, hi) for lo, hi in pegs]], manifold3d.OpType.Add)
    vertices, faces = _arrays(solid)
    return trimesh.Trimesh(vertices, faces, process=True)


#: Pad frame (u, v, w) -> (v, w, u): manifold3d slices along z, the pad's depth is u.
U_TO_Z = [[0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [1.0, 0.0, 0.0, 0.0]]


def _pocket_extent(pocket: manifold3d.Manifold, u: float) -> np.ndarray:
    """(v_min, w_min, v_max, w_max) of the pocket's cross-section at depth u."""
    return np.asarray(pocket.transform(U_TO_Z).slice(u).bounds(), dtype=float)


@pytest.mark.parametrize("angle, clearance", [(15.0, 0.0), (25.0, 0.0), (15.0, 0.3)])
def test_lead_in_widens_the_opening_by_depth_tan_angle(angle, clearance):
    config = small_config()
    sampler = config.sampler
    depth = sampler.penetration_mm
    # a 2 x 6 mm peg reaching u = D: its long side walls make it a good geometry
    mesh = _peg_part([((-1.0, 4.0, 2.0), (depth, 6.0, 8.0))])
    manifold = to_manifold(mesh)
    exact = pad_geometry(manifold, mesh.vertices, mesh.faces, np.eye(4), sampler, config.filter)
    assert exact.good
    geometry = dataclasses.replace(exact, intersection=carve(manifold, np.eye(4), SIZE, depth, clearance, angle))
    pocket = pad_box(sampler) - build_fingerpad([geometry], sampler, config.filter).pad
    near_face, near_bottom = 1e-3, depth - 0.05
    opening, bottom = _pocket_extent(pocket, near_face), _pocket_extent(pocket, near_bottom)
    widening = (near_bottom - near_face) * np.tan(np.radians(angle))
    # the cone's base polygon circumscribes its circle: at most 1/cos(pi/n) - 1 wider,
    # plus float32 vertices of manifold3d (~1e-5 mm here)
    tolerance = widening * (1.0 / np.cos(np.pi / CONE_SEGMENTS) - 1.0) + 1e-4
    for axis_low, axis_high in ((0, 2), (1, 3)):
        per_side_low = bottom[axis_low] - opening[axis_low]
        per_side_high = opening[axis_high] - bottom[axis_high]
        for per_side in (per_side_low, per_side_high):
            assert widening - 1e-4 <= per_side <= widening + tolerance, (angle, clearance, per_side, widening)
    # exact at depth: the pocket is the peg moved c deeper (METHOD §9c), so 0.05 mm above the pad's penetration it
    # is the peg widened by the draft of its last c + 0.05 mm
    tan = np.tan(np.radians(angle))
    expected_bottom = np.array([4.0, 2.0, 6.0, 8.0]) + np.array([-1.0, -1.0, 1.0, 1.0]) * (clearance + 0.05) * tan
    outward = np.array([-1.0, -1.0, 1.0, 1.0]) * (bottom - expected_bottom)
    assert np.all(np.abs(outward) <= (clearance + 0.05) * tan * (1.0 / np.cos(np.pi / CONE_SEGMENTS) - 1.0) + 1e-4), (
        outward
    )


def test_lead_in_zero_and_clearance_zero_carve_the_exact_pocket():
    config = small_config()
    mesh = _peg_part([((-1.0, 4.0, 2.0), (config.sampler.penetration_mm, 6.0, 8.0))])
    carved = carve(to_manifold(mesh), np.eye(4), SIZE, config.sampler.penetration_mm, 0.0, 0.0)
    assert carved.volume() == pytest.approx(2.0 * 6.0 * 3.0, rel=1e-6)


def test_a_sliver_below_the_minimum_wall_is_removed():
    config = small_config()
    sampler = config.sampler
    depth = sampler.penetration_mm
    # two pegs 0.3 mm apart leave a 0.3 mm pad wall between their pockets
    mesh = _peg_part([((-1.0, 1.0, 2.0), (depth, 4.0, 8.0)), ((-1.0, 4.3, 2.0), (depth, 7.0, 8.0))])
    manifold = to_manifold(mesh)
    geometry = pad_geometry(manifold, mesh.vertices, mesh.faces, np.eye(4), sampler, config.filter)
    assert geometry.good
    pad = build_fingerpad([geometry], sampler, config.filter).pad
    sliver_region = box((0.0, 4.0, 2.0), (depth - 0.5, 4.3, 8.0))
    assert (pad ^ sliver_region).volume() > 0.3 * 6.0 * 2.0
    size = (sampler.thickness_mm, sampler.length_mm, sampler.width_mm)
    assert thinnest_wall_mm(pad, *size) == pytest.approx(0.3, abs=0.01)
    opened = open_thin_walls(pad, *size, 0.8)
    # at least 99 % of it goes; what stays is where the wall joins thick pad at its ends,
    # which the ball polyhedron (<= 8.5 % beyond the ball) reaches 0.03 mm further
    assert (opened ^ sliver_region).volume() < 0.01 * sliver_region.volume()
    assert thinnest_wall_mm(opened, *size) >= 0.8 - 0.05
    assert len(opened.decompose()) == 1
    # the opening never adds material, and keeps the thick walls
    assert (opened - pad).volume() < 1e-3
    assert opened.volume() > 0.9 * (pad.volume() - 0.3 * 6.0 * depth)


def test_the_same_pad_opens_the_same_and_another_pad_or_size_differently():
    config = small_config()
    sampler = config.sampler
    depth = sampler.penetration_mm
    mesh = _peg_part([((-1.0, 1.0, 2.0), (depth, 4.0, 8.0)), ((-1.0, 4.3, 2.0), (depth, 7.0, 8.0))])

    def carved(shift_mm: float) -> manifold3d.Manifold:
        moved = mesh.copy()
        moved.apply_translation([0.0, 0.0, shift_mm])
        geometry = pad_geometry(to_manifold(moved), moved.vertices, moved.faces, np.eye(4), sampler, config.filter)
        return build_fingerpad([geometry], sampler, config.filter).pad

    size = (sampler.thickness_mm, sampler.length_mm, sampler.width_mm)
    opened = open_thin_walls(carved(0.0), *size, 0.8)
    # the same pad built again (another candidate carving it): the same opening, sliver gone
    again = open_thin_walls(carved(0.0), *size, 0.8)
    assert np.array_equal(again.to_mesh64().vert_properties, opened.to_mesh64().vert_properties)
    assert np.array_equal(again.to_mesh64().tri_verts, opened.to_mesh64().tri_verts)
    # a smaller minimum keeps the 0.3 mm wall: not the opening kept for 0.8 mm
    assert open_thin_walls(carved(0.0), *size, 0.2).volume() > opened.volume() + 0.3 * 6.0 * 1.0
    # the pegs moved 0.5 mm along w: a pad of its own, opened where it is
    moved = open_thin_walls(carved(0.5), *size, 0.8)
    assert (moved - opened).volume() > 0.5 and (opened - moved).volume() > 0.5
    assert (moved ^ box((0.0, 4.0, 2.5), (depth - 0.5, 4.3, 8.5))).volume() < 0.01 * 0.3 * 6.0 * (depth - 0.5)


def test_profiles_load_and_keys_override(tmp_path):
    # the default is the paper's printer and material (METHOD §9b): HP MJF in PA12
    assert PrintConfig().profile == "mjf-pa12"
    assert PrintConfig().resolved() == {
        "clearance_mm": 0.4,
        "lead_in_deg": 15.0,
        "min_wall_mm": 0.5,
        "density_g_cm3": 1.01,
    }
    assert PrintConfig(profile="custom").resolved() == {
        "clearance_mm": 0.0,
        "lead_in_deg": 0.0,
        "min_wall_mm": 0.0,
        "density_g_cm3": 1.01,
    }
    path = tmp_path / "fit.toml"
    path.write_text('[print]\nprofile = "fdm-pla"\nmin_wall_mm = 1.5\n')
    fit = load_config(path).print.resolved()
    # Prusa's "loose" fit, a value from the profile table; min wall from the file
    assert fit["clearance_mm"] == 0.2 and fit["min_wall_mm"] == 1.5 and fit["lead_in_deg"] == 15.0
    assert PrintConfig(profile="mjf-pa12").resolved()["clearance_mm"] == 0.4
    assert PrintConfig(profile="sla-resin", clearance_mm=0.0).resolved()["clearance_mm"] == 0.0
    path.write_text('[print]\nprofile = "sls-pa11"\n')
    with pytest.raises(ConfigError, match=r"fit\.toml.*print\.profile"):
        load_config(path)


def test_job_manifest_accepts_print():
    defaults = DesignConfig().updated({"print": {"profile": "mjf-pa12", "min_wall_mm": 0.7}})
    manifest = parse_manifest('[print]\nprofile = "sla-resin"\n', "job.toml", defaults)
    fit = manifest.design_config(defaults).print
    # the job's profile; the daemon's explicit min wall still overrides it
    assert (
        fit.profile == "sla-resin" and fit.resolved()["clearance_mm"] == 0.15 and fit.resolved()["min_wall_mm"] == 0.7
    )
    with pytest.raises(ConfigError, match=r"job\.toml.*print\.clearance_mm"):
        parse_manifest("[print]\nclearance_mm = -1\n", "job.toml", defaults)


@pytest.mark.parametrize("profile", ["custom", "mjf-pa12", "fdm-pla", "sla-resin"])
def test_every_profile_gives_one_watertight_finger(profile, tmp_path):
    config = small_config(sampler={"stride_mm": 8.0}, print={"profile": profile})
    result = fcso.design([data_path("capsela200_plug.stl"), data_path("solar_tracker.stl")], config)
    report = result.report
    assert report.finger.bodies == 1 and report.finger.watertight
    assert result.finger.is_watertight and len(result.finger.split(only_watertight=False)) == 1
    fit = report.print_fit
    assert fit.profile == profile
    if profile == "custom":
        assert fit.exact == fit.fitted
    else:
        assert fit.fitted.pocket_volume_mm3 > fit.exact.pocket_volume_mm3
        # a wall the opening could not remove is told, never delivered silently (the capture measure's candidate
        # for this pair under mjf-pa12 keeps one of 0.13 mm: the opening's limit, see the issue-46 closing note)
        thin = fit.thinnest_wall_mm < fit.min_wall_mm - 0.05
        assert thin == any("thinner than print.min_wall_mm" in w for w in report.warnings)
    if profile == "mjf-pa12":
        # report.json and report.html (rebuilt from the folder, seating again) show the printed fit
        fcso.write_outputs(result, tmp_path)
        saved = DesignReport.model_validate_json((tmp_path / "report.json").read_text(encoding="utf-8"))
        assert saved.print_fit == fit and saved.settings.print.profile == "mjf-pa12"
        rebuild_report(tmp_path)
        page = (tmp_path / "report.html").read_text(encoding="utf-8")
        assert "<h2>Printed fit</h2>" in page and "mjf-pa12" in page and "as printed" in page
        assert f"{fit.fitted.pocket_volume_mm3:.1f}" in page and f"{fit.exact.pocket_volume_mm3:.1f}" in page


def _l_shape() -> manifold3d.Manifold:
    """Two boxes, 10 x 4 x 3 and 4 x 10 x 3 mm, sharing a 4 x 4 corner: an L whose flat faces are several triangles."""
    return box((0.0, 0.0, 0.0), (10.0, 4.0, 3.0)) + box((0.0, 0.0, 0.0), (4.0, 10.0, 3.0))


def test_minkowski_sum_of_an_l_with_a_cube_is_the_union_of_the_grown_boxes():
    # L ⊕ [-1, 1]^3 is the two boxes grown by 1 mm on every side, whose union's volume is worked out by hand:
    # 12 x 6 x 5 + 6 x 12 x 5 - 6 x 6 x 5 (their common corner)
    cube = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])
    grown = minkowski_convex(_l_shape(), cube)
    assert grown.volume() == pytest.approx(12 * 6 * 5 + 6 * 12 * 5 - 6 * 6 * 5, rel=1e-9)
    assert np.allclose(grown.bounding_box(), (-1.0, -1.0, -1.0, 11.0, 11.0, 4.0))
    assert len(grown.decompose()) == 1


def test_minkowski_difference_of_an_l_by_a_cube_is_the_union_of_the_shrunk_boxes():
    # the boxes shrunk by 1 mm: 8 x 2 x 1 + 2 x 8 x 1 - 2 x 2 x 1
    cube = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])
    eroded = minkowski_difference_convex(_l_shape(), cube)
    assert eroded.volume() == pytest.approx(8 * 2 * 1 + 2 * 8 * 1 - 2 * 2 * 1, rel=1e-9)
    assert np.allclose(eroded.bounding_box(), (1.0, 1.0, 1.0, 9.0, 9.0, 2.0))


@pytest.mark.parametrize("name", sorted(FIXTURE_PARTS))
def test_minkowski_sums_of_real_parts_are_manifold3d_sums(name):
    # the lead-in cone reaches no further than its apex across the faces that face the pad's back, which are left
    # out of the sum: it must still be manifold3d's own sum of every triangle, as the clearance ball's is
    config = small_config()
    mesh, manifold, frame = _good_geometries(name, config, limit=1)[0]
    local = (
        manifold.transform(affine_3x4(frame)) ^ box((-1.0, -1.0, -1.0), tuple(x + 1.0 for x in SIZE))
    ).as_original()
    for kernel in (ball_points(0.2), cone_points(SIZE[0], 30.0)):
        ours = minkowski_convex(local, kernel)
        theirs = local.minkowski_sum(manifold3d.Manifold.hull_points(kernel))
        assert ours.volume() == pytest.approx(theirs.volume(), rel=1e-7)
        assert (ours - theirs).volume() + (theirs - ours).volume() < 1e-6 * theirs.volume()
