"""Grasps for the robot: tool-centre-point pose, approach and closing width (issue item 8)."""

from __future__ import annotations

import numpy as np
import trimesh

from .config import SamplerConfig
from .sampler import GraspSample

#: The gripper approaches from above.
APPROACH_DIRECTION = np.array([0.0, 0.0, -1.0])


def tcp_pose(sample: GraspSample, offset_plus_mm: float, offset_minus_mm: float, sampler: SamplerConfig) -> dict:
    """Tool-centre-point pose of a grasp in the part's resting frame.

    The TCP sits midway between the two seated pad faces, at the pads'
    mid-height. Its z axis is the approach direction (down), its y axis the
    closing axis ``a`` (the fingers move along ±y) and x = y × z.

    Parameters
    ----------
    sample : GraspSample
        The chosen sample.
    offset_plus_mm, offset_minus_mm : float
        Seating offsets of the "+" and "-" pads (METHOD §6).
    sampler : SamplerConfig
        Pad size.

    Returns
    -------
    dict
        ``position_mm`` (3), ``quaternion_wxyz`` (4), ``approach_direction``
        (3), ``closing_axis`` (3), ``pad_gap_mm`` (distance between the pad
        faces at contact) and ``closing_width_mm`` (distance between the
        flat fingers' contact faces at contact, what the gripper is
        commanded to).
    """
    depth, thickness = sampler.penetration_mm, sampler.thickness_mm
    a, b = sample.closing_axis, sample.sliding_axis
    centre_a = (sample.a_max_mm + sample.a_min_mm) / 2.0 + (offset_plus_mm - offset_minus_mm) / 2.0
    position = centre_a * a + sample.s_mm * b + (sample.h_mm + sampler.width_mm / 2.0) * np.array([0.0, 0.0, 1.0])
    rotation = np.eye(4)
    rotation[:3, 0], rotation[:3, 1], rotation[:3, 2] = b, a, APPROACH_DIRECTION
    quaternion = trimesh.transformations.quaternion_from_matrix(rotation)
    if quaternion[0] < 0:
        quaternion = -quaternion
    pad_gap = (sample.a_max_mm - sample.a_min_mm) - 2.0 * depth + offset_plus_mm + offset_minus_mm
    return {
        "position_mm": position.tolist(),
        "quaternion_wxyz": quaternion.tolist(),
        "approach_direction": APPROACH_DIRECTION.tolist(),
        "closing_axis": a.tolist(),
        "pad_gap_mm": float(pad_gap),
        "closing_width_mm": float(pad_gap + 2.0 * thickness),
    }


def approach_gripper_opening_mm(
    closing_width_mm: float, pad_inset_mm: float, open_margin_mm: float, max_opening_mm: float
) -> float:
    """How wide the gripper must be open as it comes down over the part (between the flat fingers' contact faces), mm:
    each pad's face ``open_margin_mm`` clear of the part's outermost point in its footprint, at most the full opening.

    A carved pad's face lies ``pad_inset_mm`` (the penetration D) inside that point at the seated grasp, a flat pad's
    at it (0): opened less, a pocket's rim lands on the part (docs/verification.md). ``closing_width_mm`` is the grasp's
    (:class:`fcso.report.models.GraspReport`). The simulation opens each finger by the same amount
    (:func:`fcso.sim.trials.approach_opening_mm`, the finger joint's q).
    """
    return min(max_opening_mm, closing_width_mm + 2.0 * (pad_inset_mm + open_margin_mm))
