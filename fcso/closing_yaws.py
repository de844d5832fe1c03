"""Closing directions beyond the configured yaws (METHOD §3b, ``[sampler] face_yaws``): square to a part's flat
side faces, and into the pockets of its outline that its convex hull bridges."""

from __future__ import annotations

import numpy as np
import trimesh

from .geometry import (
    to_manifold,
)

#: Side faces whose normal is within this of horizontal give closing directions, degrees.
SIDE_FACE_TILT_DEG = 15.0
#: Closing directions of side faces are collected in bins this wide, degrees; a bin within two bins of a
#: configured yaw adds nothing (those pads already face it).
FACE_YAW_BIN_DEG = 5.0
#: A direction is added when its faces make at least this share of the part's side area ...
FACE_YAW_MIN_SHARE = 0.05
#: ... and at most this many directions per scenario, the largest: each costs one more yaw's samples, and
#: a symmetric part (a chamfered cube, a hexagon) offers the same grasp at each of its directions.
MAX_FACE_YAWS = 1
#: Heights, as shares of the part's height, at which its outline is cut to find the pockets its convex hull bridges.
OUTLINE_LEVELS = (0.25, 0.5, 0.75)
#: A pocket of an outline smaller than this is no feature, mm².
MIN_POCKET_MM2 = 1.0
#: ... nor one whose opening (the hull edge over it) is longer than the longest default pad, mm: no pad centres on
#: it (an L's inner corner), and closing into it grips the part's corners obliquely instead of its features.
MAX_POCKET_OPENING_MM = 20.0


def face_yaws(mesh: trimesh.Trimesh, configured_deg: list[float], min_area_mm2: float) -> list[float]:
    """Closing directions normal to a part's flat side faces that the configured yaws miss (beyond METHOD §3).

    The stride and feature positions of METHOD §3b slide pads along ``b``;
    the closing axis stays at the configured yaws (the bounding-box frame's
    0 and 90 degrees by default). A part whose side faces are not square to
    that frame (a chamfered edge, a hexagon, a notch's flank) is then only
    grasped obliquely, though pads square to those faces would hold a V
    between them: measured on a 30 mm cube with chamfered vertical edges,
    closing along the bounding box captured displaced parts from one side
    only (6 of 10 simulated trials), closing square to the chamfers seated
    10 of 10. Side faces (normal within :data:`SIDE_FACE_TILT_DEG` of
    horizontal) are binned by the direction of their normal modulo 180
    degrees, weighted by area; a bin holding at least
    :data:`FACE_YAW_MIN_SHARE` of the side area and ``min_area_mm2`` per
    side, away from the configured yaws, gives its area-weighted mean
    direction of most area. Round and organic sides spread over many bins and add none.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The part in its resting frame (mm), table normal ``+z``.
    configured_deg : list of float
        ``[sampler] yaw_deg``.
    min_area_mm2 : float
        Least face area per side of a direction (the sampler's least contact area), mm².

    Returns
    -------
    list of float
        At most :data:`MAX_FACE_YAWS` yaws in [0, 180) degrees, largest side area first.
    """
    normals, areas = np.asarray(mesh.face_normals), np.asarray(mesh.area_faces)
    side = np.abs(normals[:, 2]) < np.sin(np.radians(SIDE_FACE_TILT_DEG))
    if not side.any():
        return []
    yaws = np.degrees(np.arctan2(normals[side, 1], normals[side, 0])) % 180.0
    weights = areas[side]
    bins = int(round(180.0 / FACE_YAW_BIN_DEG))
    number = np.minimum((yaws / FACE_YAW_BIN_DEG).astype(int), bins - 1)
    area = np.bincount(number, weights=weights, minlength=bins)
    # within a bin, the direction of the most face area (0.1 degree steps): a flat face's own direction,
    # not its mean with the facets of a round wall beside it
    fine = np.round(yaws, 1) % 180.0
    taken = [int(round(y / FACE_YAW_BIN_DEG)) % bins for y in np.asarray(configured_deg) % 180.0]
    chosen: list[float] = []
    for k in np.argsort(-area, kind="stable"):
        if len(chosen) == MAX_FACE_YAWS or area[k] < max(FACE_YAW_MIN_SHARE * weights.sum(), 2.0 * min_area_mm2):
            break
        # a local maximum only: one face direction can straddle two bins
        if area[k] < max(area[(k - 1) % bins], area[(k + 1) % bins]):
            continue
        if any(min((k - t) % bins, (t - k) % bins) <= 2 for t in taken):
            continue
        taken.append(int(k))
        directions, at = np.unique(fine[number == k], return_inverse=True)
        chosen.append(float(directions[np.argmax(np.bincount(at, weights=weights[number == k]))]))
    return chosen + pocket_yaws(mesh, [*configured_deg, *chosen])


def pocket_yaws(mesh: trimesh.Trimesh, taken_deg: list[float]) -> list[float]:
    """A closing direction into the pockets of a part's outline that the yaws taken miss (beyond METHOD §3).

    A notch, a slot or a gap between teeth is a pocket of the part's
    outline seen from above: a region inside its convex hull and outside
    the part. Pads closing square to the hull's face over a pocket push
    into it and carve it; closing along any other axis they meet the part
    beside it. Where the part's flat faces are square to the configured yaws
    (a block, a bar) those yaws already close into its pockets; a round or
    polygonal part's pockets can lie at any angle (a disc with a V-notch on
    each side at 30 degrees from its bounding box: neither 0, 90 nor a side
    face's direction closes into them). The outline is cut at
    :data:`OUTLINE_LEVELS` of the part's height; each pocket of at least
    :data:`MIN_POCKET_MM2` whose opening is at most
    :data:`MAX_POCKET_OPENING_MM` adds its area to the direction of the outward
    normal of the longest hull edge over it, binned modulo 180 degrees as in
    :func:`face_yaws`; the bin of most pocket area, if more than two bins
    from every yaw taken, gives the direction of its largest pocket.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The part in its resting frame (mm), table normal ``+z``.
    taken_deg : list of float
        Yaws already sampled (``[sampler] yaw_deg`` and the side faces' of :func:`face_yaws`).

    Returns
    -------
    list of float
        At most one yaw in [0, 180) degrees.
    """
    solid = to_manifold(mesh)
    low, high = float(mesh.bounds[0, 2]), float(mesh.bounds[1, 2])
    bins = int(round(180.0 / FACE_YAW_BIN_DEG))
    area = np.zeros(bins)
    largest: dict[int, tuple[float, float]] = {}  # bin -> (pocket area, direction)
    for share in OUTLINE_LEVELS:
        section = solid.slice(low + share * (high - low))
        if section.is_empty():
            continue
        hull = section.hull()
        corners = np.concatenate([np.asarray(c, dtype=float) for c in hull.to_polygons()])
        # hull edges of a counter-clockwise contour: outward normal (dy, -dx)
        ends = np.roll(corners, -1, axis=0)
        middles, lengths = (corners + ends) / 2.0, np.linalg.norm(ends - corners, axis=1)
        yaws = np.degrees(np.arctan2(-(ends - corners)[:, 0], (ends - corners)[:, 1])) % 180.0
        for pocket in (hull - section).decompose():
            pocket_area = pocket.area()
            if pocket_area < MIN_POCKET_MM2:
                continue
            over = _on_outline(middles, pocket.to_polygons())
            if not over.any():
                continue
            edge = np.flatnonzero(over)[np.argmax(lengths[over])]
            if lengths[edge] > MAX_POCKET_OPENING_MM:
                continue
            k = min(int(yaws[edge] / FACE_YAW_BIN_DEG), bins - 1)
            area[k] += pocket_area
            if pocket_area > largest.get(k, (0.0, 0.0))[0]:
                largest[k] = (pocket_area, round(float(yaws[edge]), 1) % 180.0)
    taken = [int(round(y / FACE_YAW_BIN_DEG)) % bins for y in np.asarray(taken_deg, dtype=float) % 180.0]
    for k in np.argsort(-area, kind="stable"):
        if area[k] == 0.0:
            break
        # one pocket direction can straddle two bins: the larger one speaks for both
        if area[k] < max(area[(k - 1) % bins], area[(k + 1) % bins]):
            continue
        if any(min((k - t) % bins, (t - k) % bins) <= 2 for t in taken):
            continue
        return [largest[int(k)][1]]
    return []


def _on_outline(points: np.ndarray, contours: list, tolerance_mm: float = 1e-3) -> np.ndarray:
    """Which ``points`` (n, 2) lie within ``tolerance_mm`` of a contour's edges (closed polygons)."""
    near = np.zeros(len(points), dtype=bool)
    for contour in contours:
        start = np.asarray(contour, dtype=float)
        end = np.roll(start, -1, axis=0)
        along = end - start
        length2 = np.maximum((along**2).sum(axis=1), 1e-18)
        t = np.clip(((points[:, None, :] - start[None]) * along[None]).sum(axis=2) / length2[None], 0.0, 1.0)
        closest = start[None] + t[..., None] * along[None]
        near |= (np.linalg.norm(points[:, None, :] - closest, axis=2) <= tolerance_mm).any(axis=1)
    return near
