"""Grasp sampler: every feasibility check rejects what it should (METHOD §3)."""

import manifold3d
import numpy as np
import pytest
import trimesh

from fcso import load_part, stable_poses
from fcso.config import DesignConfig, GripperConfig, SamplerConfig
from fcso.geometry import box, to_manifold, to_trimesh
from fcso.sampler import REJECTION_REASONS, sample_grasps

from .conftest import data_path

PAD = dict(length_mm=10.0, width_mm=10.0, thickness_mm=4.0, penetration_mm=3.0, stride_mm=5.0, table_clearance_mm=1.0)


def block_part() -> trimesh.Trimesh:
    """A 30 x 20 x 15 mm block resting on the table, centred in x and y."""
    return to_trimesh(box((-15.0, -10.0, 0.0), (15.0, 10.0, 15.0)))


def run(mesh, gripper=None, **sampler):
    return sample_grasps(mesh, SamplerConfig(**{**PAD, **sampler}), gripper or GripperConfig())


def test_block_counts_follow_from_its_dimensions():
    # yaw 0: s in {-5, 0, 5}, yaw 90: s in {-10, ..., 10}; h in {1, 6, 11}.
    # h = 1 leaves the block beside the finger body above the pad -> collision
    result = run(block_part(), min_contact_area_mm2=10.0)
    assert result.tried == 3 * 3 + 5 * 3
    assert result.rejected["collision_finger"] == 3 + 5
    assert len(result.samples) == 2 * 3 + 2 * 5
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
    config = DesignConfig()
    part = load_part(data_path("stanford_bunny_closed.ply"), scale_to_mm=65.0)
    transforms, _ = stable_poses(part.mesh)
    mesh = part.mesh.copy()
    mesh.apply_transform(transforms[1])
    sampler, gripper = config.sampler, config.gripper
    result = sample_grasps(mesh, sampler, gripper)
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
        for lower, upper in (((sample.a_max_mm - D, b0, h), (sample.a_max_mm - D + T, b1, h + W)),
                             ((sample.a_min_mm + D - T, b0, h), (sample.a_min_mm + D, b1, h + W))):
            assert _volume_inside(local, lower, upper) > 0.0
        # nothing of the part beyond a_max / a_min inside the footprint
        assert _volume_inside(local, (sample.a_max_mm + 1e-3, b0, h), (1e3, b1, h + W)) == pytest.approx(0.0, abs=1e-6)
        assert _volume_inside(local, (-1e3, b0, h), (sample.a_min_mm - 1e-3, b1, h + W)) == pytest.approx(0.0, abs=1e-6)
        # fits between the open pads, closes within range
        span = sample.a_max_mm - sample.a_min_mm
        assert span + sampler.table_clearance_mm <= gripper.max_opening_mm - 2 * T
        # finger bodies above the closed pads are free
        top = h + W + gripper.finger_height_mm
        assert _volume_inside(local, (sample.a_max_mm - D + 1e-3, b0, h + W), (sample.a_max_mm - D + T, b1, top)) == pytest.approx(0.0, abs=1e-6)
        assert _volume_inside(local, (sample.a_min_mm + D - T, b0, h + W), (sample.a_min_mm + D - 1e-3, b1, top)) == pytest.approx(0.0, abs=1e-6)
        assert h >= sampler.table_clearance_mm
