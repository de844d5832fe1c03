"""Grasp sampler: every feasibility check rejects what it should (METHOD §3)."""

import manifold3d
import numpy as np
import pytest
import trimesh

from examples.sim_parts import zigzag_l_part
from fcso import load_part, stable_poses
from fcso.closing_yaws import face_yaws, pocket_yaws
from fcso.config import DesignConfig, FingerConfig, GripperConfig, SamplerConfig, load_config
from fcso.finger import finger_plate, load_finger, parametric_finger
from fcso.geometry import box, to_manifold, to_trimesh
from fcso.sampler import REJECTION_REASONS, FingerPlate, feature_centres, sample_grasps
from tests.conftest import REPO, data_path

PAD = dict(length_mm=10.0, width_mm=10.0, thickness_mm=4.0, penetration_mm=3.0, stride_mm=5.0, table_clearance_mm=1.0)
#: The product's settings with the paper's one 20 x 20 mm pad (the default designs two lengths, one at a time).
PAPER_PAD = DesignConfig().updated({"sampler": {"length_mm": 20.0}})


def block_part() -> trimesh.Trimesh:
    """A 30 x 20 x 15 mm block resting on the table, centred in x and y."""
    return to_trimesh(box((-15.0, -10.0, 0.0), (15.0, 10.0, 15.0)))


def bunny_in_pose(index: int) -> trimesh.Trimesh:
    """The paper's bunny (65 mm) resting in its stable pose ``index``."""
    part = load_part(data_path("stanford_bunny_closed.ply"), scale_to_mm=65.0)
    transforms, _ = stable_poses(part.mesh)
    mesh = part.mesh.copy()
    mesh.apply_transform(transforms[index])
    return mesh


def built_in_plate(sampler: SamplerConfig, gripper: GripperConfig) -> FingerPlate:
    return finger_plate(parametric_finger(sampler, gripper), sampler, gripper)


def run(mesh, gripper=None, plate=None, **sampler):
    sampler = SamplerConfig(**{**PAD, **sampler})
    gripper = gripper or GripperConfig()
    return sample_grasps(mesh, sampler, gripper, plate or built_in_plate(sampler, gripper))


def test_built_in_plate_is_measured_from_the_finger():
    # the built-in plate is 8 mm thick and max(L + 4, 20) mm wide, centred on the pad
    plate = built_in_plate(SamplerConfig(**PAD), GripperConfig())
    assert (plate.thickness_mm, plate.v_min_mm, plate.v_max_mm) == pytest.approx((8.0, -5.0, 15.0))
    wide = built_in_plate(SamplerConfig(**{**PAD, "length_mm": 30.0, "stride_mm": 6.0}), GripperConfig())
    assert (wide.thickness_mm, wide.v_min_mm, wide.v_max_mm) == pytest.approx((8.0, -2.0, 32.0))


def test_user_finger_plate_is_its_extent_behind_the_contact_face(tmp_path):
    # a 12 mm thick, 40 mm wide, 60 mm tall bar whose contact face is x = 0, pad centred 5 mm above its tip
    path = tmp_path / "bar_finger.stl"
    to_trimesh(box((0.0, -15.0, 0.0), (12.0, 25.0, 60.0))).export(path)
    finger = load_finger(
        FingerConfig(mesh=path, contact_origin_mm=(0.0, 0.0, 10.0), contact_normal=(-1.0, 0.0, 0.0), up=(0.0, 0.0, 1.0))
    )
    sampler = SamplerConfig(**PAD)
    plate = finger_plate(finger, sampler, GripperConfig())
    # v runs along up x outward = +y from y = -L/2: y in [-15, 25] -> v in [-10, 30]
    assert (plate.thickness_mm, plate.v_min_mm, plate.v_max_mm) == pytest.approx((12.0, -10.0, 30.0))


def test_block_counts_follow_from_its_dimensions():
    # yaw 0: s in {-5, 0, 5}, yaw 90: s in {-10, ..., 10}; h in {1, 6, 11}.
    # the block's straight sides above a low pad stand in front of the finger
    # plate (u < T), so every height is valid (METHOD §3 revision 2)
    result = run(block_part(), min_contact_area_mm2=10.0)
    assert result.tried == 3 * 3 + 5 * 3
    assert result.rejected["collision_finger"] == 0
    assert len(result.samples) == 3 * 3 + 5 * 3
    assert sum(result.rejected.values()) + len(result.samples) == result.tried
    assert set(result.rejected) == set(REJECTION_REASONS)


def test_contact_check_threshold():
    # h = 11: 10 x 4 mm of side face plus a 3 x 10 mm strip of the top inside
    # the box = 70 mm²; at the block's ends the box also holds 3 x 4 mm of the
    # end face = 82 mm². Inner footprints: 1 for yaw 0, 3 for yaw 90.
    strict = run(block_part(), min_contact_area_mm2=71.0)
    assert strict.rejected["contact"] == 1 + 3
    lenient = run(block_part(), min_contact_area_mm2=69.0)
    assert lenient.rejected["contact"] == 0
    areas = {round(s.area_plus_mm2, 6) for s in lenient.samples if s.h_mm == 11.0}
    assert areas == {70.0, 82.0}
    assert {round(s.area_minus_mm2, 6) for s in lenient.samples if s.h_mm == 11.0} == {70.0, 82.0}


def test_fit_check_open_and_closed():
    # yaw 0 spans 30 mm: it needs 30 + 1 clearance + 2 T = 39 mm of opening
    narrow = run(block_part(), GripperConfig(max_opening_mm=38.5), min_contact_area_mm2=10.0)
    assert narrow.rejected["fit"] == 9 and all(s.yaw_deg == 90.0 for s in narrow.samples)
    wide_enough = run(block_part(), GripperConfig(max_opening_mm=39.0), min_contact_area_mm2=10.0)
    assert wide_enough.rejected["fit"] == 0
    # closed, the mounting faces are span - 2D + 2T apart: 22 mm for yaw 90
    no_close = run(block_part(), GripperConfig(min_opening_mm=25.0), min_contact_area_mm2=10.0)
    assert no_close.rejected["fit"] == 15 and all(s.yaw_deg == 0.0 for s in no_close.samples)


def test_descent_column_hits_an_overhanging_cap():
    # base 30 x 20 x 10, a 10 mm neck up to 35, then a 60 mm wide cap: the open
    # pads (21 mm from the centre) cannot pass the cap on the way down
    base = box((-15.0, -10.0, 0.0), (15.0, 10.0, 10.0))
    neck = box((-5.0, -10.0, 9.0), (5.0, 10.0, 35.0))
    cap = box((-30.0, -10.0, 35.0), (30.0, 10.0, 38.0))
    mesh = to_trimesh(manifold3d.Manifold.batch_boolean([base, neck, cap], manifold3d.OpType.Add))
    result = run(mesh, GripperConfig(finger_height_mm=5.0), yaw_deg=[0.0], min_contact_area_mm2=10.0)
    assert result.rejected["collision_descent"] > 0
    assert all(s.h_mm >= 30.0 for s in result.samples)
    without_cap = to_trimesh(base + neck)
    clear = run(without_cap, GripperConfig(finger_height_mm=5.0), yaw_deg=[0.0], min_contact_area_mm2=10.0)
    assert clear.rejected["collision_descent"] == 0


def _volume_inside(part: manifold3d.Manifold, lower, upper) -> float:
    return (part ^ box(lower, upper)).volume()


def test_valid_bunny_samples_pass_every_check_independently():
    config = PAPER_PAD
    mesh = bunny_in_pose(1)
    sampler, gripper = config.sampler, config.gripper
    plate = built_in_plate(sampler, gripper)
    result = sample_grasps(mesh, sampler, gripper, plate)
    assert len(result.samples) > 0
    assert result.tried == len(result.samples) + sum(result.rejected.values())
    solid = to_manifold(mesh)
    T, D, L, W = sampler.thickness_mm, sampler.penetration_mm, sampler.length_mm, sampler.width_mm
    for sample in result.samples[:: max(1, len(result.samples) // 8)]:
        # everything in the closing-axis frame (a, b, z) by a rotation about z
        turn = np.eye(4)
        turn[0, :3], turn[1, :3] = sample.closing_axis, sample.sliding_axis
        local = solid.transform(turn[:3].tolist())
        b0, b1, h = sample.s_mm - L / 2, sample.s_mm + L / 2, sample.h_mm
        # contact: the part really reaches D into both pad boxes
        for lower, upper in (
            ((sample.a_max_mm - D, b0, h), (sample.a_max_mm - D + T, b1, h + W)),
            ((sample.a_min_mm + D - T, b0, h), (sample.a_min_mm + D, b1, h + W)),
        ):
            assert _volume_inside(local, lower, upper) > 0.0
        # nothing of the part beyond a_max / a_min inside the footprint
        assert _volume_inside(local, (sample.a_max_mm + 1e-3, b0, h), (1e3, b1, h + W)) == pytest.approx(0.0, abs=1e-6)
        assert _volume_inside(local, (-1e3, b0, h), (sample.a_min_mm - 1e-3, b1, h + W)) == pytest.approx(0.0, abs=1e-6)
        # fits between the open pads, closes within range
        span = sample.a_max_mm - sample.a_min_mm
        assert span + sampler.table_clearance_mm <= gripper.max_opening_mm - 2 * T
        # the 8 mm, 24 mm wide plates behind the closed pads are free
        top = h + W + gripper.finger_height_mm
        plus_back, minus_back = sample.a_max_mm - D + T, sample.a_min_mm + D - T
        assert _volume_inside(local, (plus_back, b0 - 2.0, h), (plus_back + 8.0, b1 + 2.0, top)) == pytest.approx(
            0.0, abs=1e-6
        )
        assert _volume_inside(local, (minus_back - 8.0, b0 - 2.0, h), (minus_back, b1 + 2.0, top)) == pytest.approx(
            0.0, abs=1e-6
        )
        assert h >= sampler.table_clearance_mm


def test_cube_is_gripped_below_its_top():
    # METHOD §3 revision 2: straight sides stand in front of the finger plate
    mesh = load_part(data_path("20mm-xyz-cube.stl")).mesh.copy()
    mesh.apply_translation(-mesh.bounds[0] * [0.0, 0.0, 1.0] - mesh.centroid * [1.0, 1.0, 0.0])
    top = float(mesh.bounds[1, 2])
    result = run(mesh, min_contact_area_mm2=10.0)
    low = [s for s in result.samples if s.h_mm + PAD["width_mm"] <= top - 5.0]
    assert len(low) >= 2
    assert {s.yaw_deg for s in low} == {0.0, 90.0}


def _stem_with_cap(overhang_mm: float) -> trimesh.Trimesh:
    """A 20 mm stem up to z = 20 under a 5 mm cap reaching ``overhang_mm`` beyond it along x."""
    stem = box((-10.0, -10.0, 0.0), (10.0, 10.0, 20.0))
    cap = box((-10.0 - overhang_mm, -10.0, 19.9), (10.0 + overhang_mm, 10.0, 25.0))
    return to_trimesh(stem + cap)


def test_undercut_reaching_the_plate_is_rejected():
    # T - D = 1 mm: a cap overhanging the stem by 3 mm reaches u >= T above
    # every pad on the stem, so the finger plate hits it
    capped = run(_stem_with_cap(3.0), yaw_deg=[0.0], min_contact_area_mm2=10.0)
    on_stem = [s for s in capped.samples if s.h_mm + PAD["width_mm"] <= 19.9]
    assert on_stem == []
    assert capped.rejected["collision_finger"] == 3 * 2  # s in {-5, 0, 5}, h in {1, 6}
    assert capped.rejected["collision_descent"] == 0
    # a 0.5 mm lip stays in front of the plate (u < T): the stem is gripped below it
    lipped = run(_stem_with_cap(0.5), yaw_deg=[0.0], min_contact_area_mm2=10.0)
    assert lipped.rejected["collision_finger"] == 0
    assert len([s for s in lipped.samples if s.h_mm + PAD["width_mm"] <= 19.9]) == 3 * 2


def test_thicker_plate_meets_what_a_thin_one_misses():
    # a stem and, beside its top, two loose bars 3 mm out (the sampler takes any
    # closed mesh): the plate's front face is at x = 10 - D + T = 11, so a plate
    # 1.5 mm thick ends short of the bars at x = 13 and a 3 mm one reaches them
    stem = box((-10.0, -10.0, 0.0), (10.0, 10.0, 20.0))
    bars = box((13.0, -10.0, 19.9), (20.0, 10.0, 25.0)) + box((-20.0, -10.0, 19.9), (-13.0, 10.0, 25.0))
    mesh = to_trimesh(stem + bars)
    sampler = SamplerConfig(**{**PAD, "yaw_deg": [0.0]})
    gripper = GripperConfig(max_opening_mm=80.0)
    thin = sample_grasps(mesh, sampler, gripper, FingerPlate(thickness_mm=1.5, v_min_mm=0.0, v_max_mm=10.0))
    thick = sample_grasps(mesh, sampler, gripper, FingerPlate(thickness_mm=3.0, v_min_mm=0.0, v_max_mm=10.0))
    low = lambda result: [s for s in result.samples if s.h_mm + PAD["width_mm"] <= 19.9]  # noqa: E731
    assert len(low(thin)) == 3 * 2
    assert low(thick) == []
    assert thick.rejected["collision_finger"] == 3 * 2


def test_paper_bunny_has_base_level_grasps():
    # the paper found grasps "along the extrusions at the base" (METHOD §10)
    config = load_config(REPO / "examples" / "paper.toml")
    mesh = bunny_in_pose(1)
    result = sample_grasps(mesh, config.sampler, config.gripper, built_in_plate(config.sampler, config.gripper))
    assert any(s.h_mm <= 10.0 for s in result.samples)


def test_every_nth_pad_position_together_make_the_whole_sampling():
    config = PAPER_PAD
    mesh = bunny_in_pose(1)
    plate = built_in_plate(config.sampler, config.gripper)
    whole = sample_grasps(mesh, config.sampler, config.gripper, plate)
    subsets = [sample_grasps(mesh, config.sampler, config.gripper, plate, (k, 3)) for k in range(3)]
    assert sum(r.tried for r in subsets) == whole.tried
    assert {reason: sum(r.rejected[reason] for r in subsets) for reason in REJECTION_REASONS} == whole.rejected
    assert {(s.yaw_deg, s.s_mm, s.h_mm) for r in subsets for s in r.samples} == {
        (s.yaw_deg, s.s_mm, s.h_mm) for s in whole.samples
    }
    positions = [{(s.yaw_deg, s.s_mm) for s in r.samples} for r in subsets]
    assert all(not (p & q) for p in positions for q in positions if p is not q)


def test_pads_centre_on_notches_inside_a_face_and_at_its_ends():
    # a 30 mm cube centred on the origin with 45-degree notches along its vertical edges, 6 mm squares turned
    # about z: seen along x, each notch cuts 3 sqrt(2) = 4.24 mm into the face's ends (|y| from 10.76 to 15)
    from examples.sim_parts import holed_notched_cube

    cube = holed_notched_cube(size_mm=30.0, hole_mm=8.0, notch_mm=6.0)
    along_b, _ = feature_centres(np.asarray(cube.vertices), np.asarray(cube.faces))
    notch_middle = 15.0 - 3.0 * np.sqrt(2.0) / 2.0
    for expected in (-notch_middle, notch_middle):
        assert np.min(np.abs(along_b - expected)) <= 0.3, along_b
    # and the face between them, whose middle a pocket holds: the plateau's middle
    assert np.min(np.abs(along_b)) <= 0.3
    # a plain box has no notches: only its face's middle
    plain, _ = feature_centres(np.asarray(block_part().vertices), np.asarray(block_part().faces))
    assert len(plain) <= 1


def chamfered_block(size_mm: float = 30.0, chamfer_mm: float = 6.0) -> trimesh.Trimesh:
    """A cube resting on the table with its four vertical edges chamfered at 45 degrees (chamfer faces
    ``chamfer_mm`` wide, normals at 45, 135, 225 and 315 degrees)."""
    half = size_mm / 2.0
    cube = manifold3d.Manifold.cube([size_mm, size_mm, size_mm], center=True).translate([0.0, 0.0, half])
    # a square turned 45 degrees about z, centred on an edge, cuts a chamfer as wide as the square's side
    cutter = manifold3d.Manifold.cube([chamfer_mm, chamfer_mm, size_mm + 2.0], center=True).rotate([0.0, 0.0, 45.0])
    for x, y in ((-half, -half), (-half, half), (half, -half), (half, half)):
        cube = cube - cutter.translate([x, y, half])
    return to_trimesh(cube)


def test_closing_axes_square_to_side_faces_the_configured_yaws_miss():
    # by construction: the chamfers face 45 and 135 degrees (modulo 180); either diagonal holds a V
    assert face_yaws(chamfered_block(), [0.0, 90.0], 40.0) in ([45.0], [135.0])
    # pads already square to them: nothing to add
    assert face_yaws(chamfered_block(), [0.0, 45.0, 90.0, 135.0], 40.0) == []
    # chamfers narrower than the least contact area per side add nothing: 2 x 1 mm x 30 mm < 2 x 40 mm^2
    assert face_yaws(chamfered_block(chamfer_mm=1.0), [0.0, 90.0], 40.0) == []
    # a hexagonal prism with a corner on x: faces at 30, 90 and 150 degrees, 90 configured
    hexagon = to_trimesh(manifold3d.Manifold.cylinder(20.0, 12.0, circular_segments=6))
    assert face_yaws(hexagon, [0.0, 90.0], 40.0) in ([30.0], [150.0])
    # a plain box and a round cylinder: no side face the configured yaws miss
    assert face_yaws(block_part(), [0.0, 90.0], 40.0) == []
    cylinder = to_trimesh(manifold3d.Manifold.cylinder(30.0, 15.0, circular_segments=96))
    assert face_yaws(cylinder, [0.0, 90.0], 40.0) == []


def test_closing_axes_into_the_pockets_of_the_outline_the_taken_yaws_miss():
    # by construction: a 4 mm deep 90-degree V-notch in each side of a round 10 mm plate, on an axis 60 degrees
    # from x
    wedge = manifold3d.Manifold.extrude(manifold3d.CrossSection([[[0.0, 0.0], [5.0, -5.0], [5.0, 5.0]]]), 12.0)
    plate = manifold3d.Manifold.cylinder(10.0, 15.0, circular_segments=96)
    for angle in (60.0, 240.0):
        plate = plate - wedge.translate([11.0, 0.0, -1.0]).rotate([0.0, 0.0, angle])
    notched = to_trimesh(plate)
    assert pocket_yaws(notched, [0.0, 90.0]) == [60.0]
    assert pocket_yaws(notched, [0.0, 60.0, 90.0]) == []
    # convex parts have no pockets: a chamfered block, a hexagon, a round cylinder
    hexagon = to_trimesh(manifold3d.Manifold.cylinder(20.0, 12.0, circular_segments=6))
    cylinder = to_trimesh(manifold3d.Manifold.cylinder(30.0, 15.0, circular_segments=96))
    for convex in (chamfered_block(), hexagon, cylinder):
        assert pocket_yaws(convex, [0.0, 90.0]) == []
    # an L's inner corner is wider than any pad: no feature (the L-part's notches face the configured 90 degrees)
    assert pocket_yaws(zigzag_l_part(), [0.0, 90.0]) == []


def test_pads_that_would_meet_beside_a_thin_section_are_rejected():
    # a fin along y standing 20 mm on a 30 x 30 x 4 mm base, closed along x; 10 mm pads, D = 3 mm. Seated on a fin
    # thinner than 2D each pad's inner face lies D inside it, so the two pad boxes overlap. Where the fin fills
    # that overlap both pads are carved away there; where a pad box reaches above the fin's top (24 mm) nothing
    # fills it, both pads keep material there and the fingers meet before the part is seated.
    def fin_part(thickness_mm: float) -> trimesh.Trimesh:
        base = box((-15.0, -15.0, 0.0), (15.0, 15.0, 4.0))
        fin = box((-thickness_mm / 2.0, -15.0, 4.0), (thickness_mm / 2.0, 15.0, 24.0))
        return to_trimesh(base + fin)

    sampler = dict(yaw_deg=[0.0], min_contact_area_mm2=5.0)
    depth, width, top = PAD["penetration_mm"], PAD["width_mm"], 24.0
    # 6.5 mm > 2D: the faces never cross, even where the pads reach above the top
    thick = run(fin_part(6.5), **sampler)
    assert thick.rejected["collision_pads"] == 0
    assert any(g.h_mm + width > top and g.a_max_mm - g.a_min_mm < 7.0 for g in thick.samples)
    # 4 mm < 2D: the pads reaching above the top are rejected, those on the fin alone are kept
    thin = run(fin_part(4.0), **sampler)
    assert thin.rejected["collision_pads"] > 0
    crossing = [g for g in thin.samples if g.a_max_mm - g.a_min_mm < 2.0 * depth]
    assert crossing and all(g.h_mm + width <= top + 1e-9 for g in crossing)
