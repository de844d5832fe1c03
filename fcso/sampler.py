"""Sliding-window grasp sampler with its feasibility checks (METHOD §3)."""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import manifold3d
import numpy as np
import trimesh

from .config import GripperConfig, SamplerConfig
from .geometry import (
    box,
    clip_to_box,
    corner_extremes,
    cut_at_levels,
    half_space_area,
    to_manifold,
    triangle_areas_normals,
)
from .grid import ScreenGrid, column_heights

#: Rejection reasons, in the order the checks run.
REJECTION_REASONS = ("contact", "fit", "collision_pads", "collision_finger", "collision_descent")
#: The pads meet when the material they would share at the seat, beside the part, exceeds this share of the
#: box where their inner faces cross.
PADS_MEET_SHARE = 0.01

#: Sides of a grasp: the "+" pad and the "-" pad.
SIDES = (1, -1)

_INF = np.inf
#: Resolution of the extent profiles that find features, mm, and the least dip that is one.
PROFILE_STEP_MM = 0.25
FEATURE_DEPTH_MM = 0.2


@dataclass(frozen=True)
class GraspSample:
    """One valid pair of pad boxes for a part in a resting pose.

    Coordinates are in the resting frame (mm): closing axis ``a``, sliding
    axis ``b = z x a``, both horizontal unit vectors.

    Attributes
    ----------
    yaw_deg : float
        Angle of ``a`` from the resting frame's x axis, degrees.
    s_mm, h_mm : float
        Footprint centre along ``b`` and footprint bottom height.
    a_max_mm, a_min_mm : float
        Part's extreme coordinates along ``a`` inside the footprint prism.
    area_plus_mm2, area_minus_mm2 : float
        Part surface inside the "+" and "-" pad boxes.
    on_feature : bool
        ``s`` or ``h`` was centred on a feature of the part (METHOD §3b), not taken from the stride.
    """

    yaw_deg: float
    s_mm: float
    h_mm: float
    a_max_mm: float
    a_min_mm: float
    area_plus_mm2: float
    area_minus_mm2: float
    on_feature: bool = False

    @property
    def closing_axis(self) -> np.ndarray:
        yaw = np.radians(self.yaw_deg)
        return np.array([np.cos(yaw), np.sin(yaw), 0.0])

    @property
    def sliding_axis(self) -> np.ndarray:
        return np.cross([0.0, 0.0, 1.0], self.closing_axis)

    def pad_frame(self, side: int, sampler: SamplerConfig) -> np.ndarray:
        """4x4 transform from the resting frame to the pad frame of one side.

        Parameters
        ----------
        side : {+1, -1}
            The "+" pad (``u = +a``) or the "-" pad (``u = -a``, the "+" pad
            turned 180 degrees about the vertical).
        sampler : SamplerConfig
            For L and D.

        Returns
        -------
        (4, 4) float
            Maps resting-frame points to pad coordinates ``(u, v, w)`` in
            which the pad box is ``[0, T] x [0, L] x [0, W]`` and the part's
            outermost point in the footprint lies at ``u = D``.
        """
        a, b = self.closing_axis, self.sliding_axis
        length, depth = sampler.length_mm, sampler.penetration_mm
        matrix = np.eye(4)
        matrix[0, :3] = side * a
        matrix[1, :3] = side * b
        matrix[2, :3] = [0.0, 0.0, 1.0]
        if side > 0:
            matrix[:3, 3] = [-(self.a_max_mm - depth), -(self.s_mm - length / 2.0), -self.h_mm]
        else:
            matrix[:3, 3] = [self.a_min_mm + depth, self.s_mm + length / 2.0, -self.h_mm]
        return matrix


@dataclass(frozen=True)
class FingerPlate:
    """The flat finger's body that carries a pad, in that pad's frame (METHOD §3, item 3).

    The plate starts at the pad's back face: it spans ``u in [T, T + thickness_mm]``,
    ``v in [v_min_mm, v_max_mm]`` (the pad spans ``[0, L]``) and runs from the
    pad's bottom edge ``w = 0`` to ``W + finger_height_mm``. Beside the pad
    the plate is as wide as the real finger, so part material there counts too.

    Attributes
    ----------
    thickness_mm : float
        Plate thickness behind the pad's back face, mm.
    v_min_mm, v_max_mm : float
        Plate extent along the pad length, mm.
    """

    thickness_mm: float
    v_min_mm: float
    v_max_mm: float


@dataclass
class SamplerResult:
    """Valid samples of one scenario and what was rejected (reason -> count)."""

    samples: list[GraspSample]
    rejected: dict[str, int]
    tried: int


def sample_grasps(
    mesh: trimesh.Trimesh,
    sampler: SamplerConfig,
    gripper: GripperConfig,
    plate: FingerPlate,
    centres: tuple[int, int] = (0, 1),
) -> SamplerResult:
    """Slide a pair of pad boxes over a part resting on the table.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The part in its resting frame (mm): table at z = 0, approach from +z.
    sampler : SamplerConfig
        Pad size L, W, T, penetration D, stride, yaw angles, table clearance,
        least contact area.
    gripper : GripperConfig
        Opening range and finger height.
    plate : FingerPlate
        The flat finger's plate behind each pad (:func:`fcso.finger.finger_plate`).
    centres : (k, n)
        Try every n-th pad position along the sliding axis from the k-th
        (``(0, 1)``: all), so one scenario can be spread over workers.

    Returns
    -------
    SamplerResult
        Valid samples in the order (yaw, s, h) they were generated, and the
        count of rejections per reason in :data:`REJECTION_REASONS`.
    """
    length, width = sampler.length_mm, sampler.width_mm
    stride, clearance = sampler.stride, sampler.table_clearance_mm
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    top = float(vertices[:, 2].max())
    rejected = {reason: 0 for reason in REJECTION_REASONS}
    samples: list[GraspSample] = []
    tried = 0
    for yaw_deg in sampler.yaw_deg:
        yaw = np.radians(yaw_deg)
        a = np.array([np.cos(yaw), np.sin(yaw), 0.0])
        b = np.cross([0.0, 0.0, 1.0], a)
        # (a, b, z) coordinates: every footprint and plate is an axis-aligned box here
        local = np.column_stack([vertices @ a, vertices @ b, vertices[:, 2]])
        b_min, b_max = local[:, 1].min(), local[:, 1].max()
        positions = np.arange(b_min + length / 2.0, b_max - length / 2.0 + 1e-9, stride)
        if len(positions) == 0:
            positions = np.array([(b_min + b_max) / 2.0])
        feature_heights = np.zeros(0)
        if sampler.feature_positions:
            # pads centred on notches, holes and gaps, which the stride may straddle (METHOD §3b)
            along_b, along_z = feature_centres(local, faces)
            positions = _merge_positions(positions, along_b)
            feature_heights = along_z - width / 2.0
            feature_heights = feature_heights[(feature_heights >= clearance) & (feature_heights < top)]
        stride_positions = set(np.arange(b_min + length / 2.0, b_max - length / 2.0 + 1e-9, stride).tolist())
        stride_heights = np.arange(clearance, top, stride)
        heights = _merge_positions(stride_heights, feature_heights)
        # the part as a solid in (a, b, z), made when a thin section first needs it
        part_solid = functools.cache(functools.partial(_solid, local, faces))
        for s in positions[centres[0] :: centres[1]]:
            found, tried_here = _samples_at(
                local,
                faces,
                float(yaw_deg),
                s,
                s in stride_positions,
                heights,
                stride_heights,
                sampler,
                gripper,
                plate,
                part_solid,
                rejected,
            )
            samples += found
            tried += tried_here
    return SamplerResult(samples=samples, rejected=rejected, tried=tried)


def _samples_at(
    local: np.ndarray,
    faces: np.ndarray,
    yaw_deg: float,
    s: float,
    on_stride: bool,
    heights: np.ndarray,
    stride_heights: np.ndarray,
    sampler: SamplerConfig,
    gripper: GripperConfig,
    plate: FingerPlate,
    part_solid: Callable[[], manifold3d.Manifold],
    rejected: dict[str, int],
) -> tuple[list[GraspSample], int]:
    """The valid samples of one pad position ``s`` along the sliding axis of one yaw, at every height, and how many
    heights had any part between the pads (:func:`sample_grasps`; ``local``: the part in (a, b, z); ``on_stride``:
    ``s`` is a stride position, not only a feature's; rejections counted into ``rejected``)."""
    length, width = sampler.length_mm, sampler.width_mm
    thickness, depth = sampler.thickness_mm, sampler.penetration_mm
    clearance = sampler.table_clearance_mm
    open_half = gripper.max_opening_mm / 2.0
    plate_height = width + gripper.finger_height_mm
    samples: list[GraspSample] = []
    tried = 0
    slab_v, slab_f = clip_to_box(local, faces, (-_INF, s - length / 2.0, -_INF), (_INF, s + length / 2.0, _INF))
    if len(slab_f) == 0:
        return [], 0
    # "+" plate: v = b - (s - L/2); "-" plate: v = (s + L/2) - b
    plate_b = {
        1: (s - length / 2.0 + plate.v_min_mm, s - length / 2.0 + plate.v_max_mm),
        -1: (s + length / 2.0 - plate.v_max_mm, s + length / 2.0 - plate.v_min_mm),
    }
    plate_slabs = {
        side: _Slab(*clip_to_box(local, faces, (-_INF, low, -_INF), (_INF, high, _INF)))
        for side, (low, high) in plate_b.items()
    }
    bands = Bands(slab_v, slab_f, np.concatenate([heights, heights + width]))
    for h in heights:
        prism_v, prism_f, prism_areas, extent = bands.between(h, h + width)
        if len(prism_f) == 0:
            continue
        tried += 1
        a_min, a_max = extent
        area_plus = half_space_area(prism_v, prism_f, prism_areas, 0, 1.0, a_max - depth)
        area_minus = half_space_area(prism_v, prism_f, prism_areas, 0, -1.0, -(a_min + depth))
        if min(area_plus, area_minus) < sampler.min_contact_area:
            rejected["contact"] += 1
            continue
        span = a_max - a_min
        fits_open = span + clearance <= gripper.max_opening_mm - 2.0 * thickness
        fits_closed = span - 2.0 * depth + 2.0 * thickness >= gripper.min_opening_mm
        if not (fits_open and fits_closed):
            rejected["fit"] += 1
            continue
        # seated, each pad's inner face lies D inside the part's extent: across a section thinner than 2D
        # the two pad boxes overlap, and where the part does not fill that overlap both pads keep material
        # there, so the fingers meet before the part is seated (the paper's bunny by its ear: 1.4 mm)
        if span < 2.0 * depth:
            crossing = box((a_max - depth, s - length / 2.0, h), (a_min + depth, s + length / 2.0, h + width))
            empty_mm3 = crossing.volume() - (crossing ^ part_solid()).volume()
            if empty_mm3 > PADS_MEET_SHARE * crossing.volume():
                rejected["collision_pads"] += 1
                continue
        closed_back = {1: a_max - depth + thickness, -1: a_min + depth - thickness}
        if any(
            plate_slabs[side].meets_box(
                *_plate_box(closed_back[side], side, plate.thickness_mm, plate_b[side], h, h + plate_height)
            )
            for side in SIDES
        ):
            rejected["collision_finger"] += 1
            continue
        centre = (a_max + a_min) / 2.0
        column = bands.above(h)
        open_back = {1: centre + open_half, -1: centre - open_half}
        if (
            column is not None
            and (column[1] > centre + open_half - thickness or column[0] < centre - open_half + thickness)
        ) or any(
            plate_slabs[side].meets_box(*_plate_box(open_back[side], side, plate.thickness_mm, plate_b[side], h, _INF))
            for side in SIDES
        ):
            rejected["collision_descent"] += 1
            continue
        samples.append(
            GraspSample(
                yaw_deg=yaw_deg,
                s_mm=float(s),
                h_mm=float(h),
                a_max_mm=a_max,
                a_min_mm=a_min,
                area_plus_mm2=area_plus,
                area_minus_mm2=area_minus,
                on_feature=bool(not on_stride or not np.isin(h, stride_heights)),
            )
        )
    return samples, tried


def _solid(local: np.ndarray, faces: np.ndarray) -> manifold3d.Manifold:
    return to_manifold(trimesh.Trimesh(local, faces, process=False))


def feature_centres(local: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where pads centre on a part's features: along ``b`` and along the height (METHOD §3b).

    The part is seen from each side of the closing axis as a map of its
    outermost ``a`` over ``(b, z)`` cells :data:`PROFILE_STEP_MM` wide. Along
    every row of the map (and every column), a stretch that dips below the
    lower of the highest values on either side by at least
    :data:`FEATURE_DEPTH_MM` is a concave interval: a notch, a hole, a gap
    between teeth. The same test on the negated map finds convex intervals
    (ribs, teeth, ridges), on whose middle a pocket holds the whole
    feature, and a stretch along ``b`` that dips below the highest value
    before it and runs on to the part's end is a notch or a chamfer at an
    end, on whose middle a pad wraps the part's end. Cells that dip in at
    least four rows (1 mm of height) make up the intervals along ``b``
    whose middles are returned, and likewise along the height, for each
    kind of interval apart.

    Parameters
    ----------
    local : (n, 3) float
        Part vertices in ``(a, b, z)`` coordinates, mm.
    faces : (m, 3) int

    Returns
    -------
    along_b, along_z : (k,) float
        Feature centres, mm, ascending.
    """
    low = local.min(axis=0)
    extent = local.max(axis=0) - low
    count_b, count_z = int(np.ceil(extent[1] / PROFILE_STEP_MM)), int(np.ceil(extent[2] / PROFILE_STEP_MM))
    if count_b < 3 or count_z < 3:
        return np.zeros(0), np.zeros(0)
    grid = ScreenGrid(PROFILE_STEP_MM, count_b, count_z)
    # concave intervals (notches, holes, gaps between teeth), convex ones (ribs, teeth, ridges) and notches
    # at the part's ends, apart: a rib and the notch beside it are two places for a pad, not one
    concave, convex, at_ends = (np.zeros((count_b, count_z), dtype=bool) for _ in range(3))
    for side in (1.0, -1.0):
        # u = outward distance along this side's a, shifted positive: 0 stays "no surface"
        seen = np.column_stack(
            [side * local[:, 0] - (side * local[:, 0]).min() + 1.0, local[:, 1] - low[1], local[:, 2] - low[2]]
        )
        outermost = column_heights(seen, faces, grid).reshape(count_b, count_z)
        outermost = np.where(outermost > 0, outermost, -np.inf)
        inward = np.where(np.isfinite(outermost), -outermost, -np.inf)
        concave |= _dips(outermost) | _dips(outermost.T).T
        convex |= _dips(inward) | _dips(inward.T).T
        # a notch or a chamfer at an end of the part along b: a pad centred on it wraps that end
        at_ends |= _end_dips(outermost) | _end_dips(outermost[::-1])[::-1]
    centres = ([], [])
    for dips in (concave, convex, at_ends):
        for number, (axis, origin) in enumerate(((1, low[1]), (0, low[2]))):
            # along b: cells dipping in >= 4 rows of the height; along z: in >= 4 columns of b
            run = dips.sum(axis=axis) >= 4
            starts = np.flatnonzero(run & ~np.concatenate([[False], run[:-1]]))
            ends = np.flatnonzero(run & ~np.concatenate([run[1:], [False]]))
            centres[number].append(origin + ((starts + ends) / 2.0 + 0.5) * PROFILE_STEP_MM)
    return np.unique(np.concatenate(centres[0])), np.unique(np.concatenate(centres[1]))


def _end_dips(heights: np.ndarray) -> np.ndarray:
    """Cells of each row (along axis 0) at least :data:`FEATURE_DEPTH_MM` below the highest before them, in a
    stretch that runs on to the row's end: a corner notch or a chamfer, which :func:`_dips` misses (no rim
    beyond it holds water)."""
    finite = np.isfinite(heights)
    with np.errstate(invalid="ignore"):
        low = finite & (np.maximum.accumulate(heights, axis=0) - heights >= FEATURE_DEPTH_MM)
    return low & np.logical_and.accumulate((low | ~finite)[::-1], axis=0)[::-1]


def _dips(heights: np.ndarray) -> np.ndarray:
    """Cells of each row (along axis 0) lying at least :data:`FEATURE_DEPTH_MM` below the water level of that row."""
    left = np.maximum.accumulate(heights, axis=0)
    right = np.maximum.accumulate(heights[::-1], axis=0)[::-1]
    level = np.minimum(left, right)
    with np.errstate(invalid="ignore"):
        return np.isfinite(level) & (level - heights >= FEATURE_DEPTH_MM)


def _merge_positions(stride: np.ndarray, features: np.ndarray) -> np.ndarray:
    """Stride positions plus the feature positions not within 0.05 mm of one of them, ascending."""
    features = np.asarray(features, dtype=float)
    if len(stride) and len(features):
        features = features[np.min(np.abs(features[:, None] - stride[None, :]), axis=1) > 0.05]
    return np.unique(np.concatenate([stride, features]))


def _plate_box(back_face_a: float, side: int, plate_thickness: float, b_range, z_low: float, z_high: float):
    """Corners (a, b, z) of a finger plate whose front lies on a pad's back face at ``back_face_a``."""
    a_low, a_high = sorted((back_face_a, back_face_a + side * plate_thickness))
    return (a_low, b_range[0], z_low), (a_high, b_range[1], z_high)


class _Slab:
    """The part surface inside a slab of the sliding axis, for exact box-intersection tests.

    Parameters
    ----------
    vertices, faces : ndarray
        The part surface clipped to the slab, ``(a, b, z)`` coordinates.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        self.vertices, self.faces = vertices, faces
        self.triangles = vertices[faces] if len(faces) else np.zeros((0, 3, 3))
        self.lower, self.upper = corner_extremes(self.triangles) if len(faces) else (np.zeros((0, 3)),) * 2

    def meets_box(self, lower, upper) -> bool:
        """Whether the part's solid intersects the box ``[lower, upper]`` (within the slab), exactly.

        The solid meets the box when its surface enters the box; with no
        surface inside, the box is wholly inside or wholly outside the
        solid, and the parity of the surface crossings of one ray from a
        point of the box decides.
        """
        if len(self.faces) == 0:
            return False
        lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
        near = np.all(self.upper >= lower, axis=1) & np.all(self.lower <= upper, axis=1)
        if near.any() and len(clip_to_box(self.vertices, self.faces[near], lower, upper)[1]):
            return True
        span_low, span_high = self.lower.min(axis=0), self.upper.max(axis=0)
        if np.any(upper < span_low) or np.any(lower > span_high):
            return False
        point = np.clip((lower + upper) / 2.0, span_low, span_high)
        return _inside(self.triangles, point)


def _inside(triangles: np.ndarray, point: np.ndarray) -> bool:
    """Whether ``point`` lies inside the closed surface ``triangles`` (parity of crossings of a ray along +a).

    Only triangles of the slab are given: a ray along ``a`` stays in the slab,
    so it crosses exactly the surface the slab holds.
    """
    b, z = triangles[:, :, 1], triangles[:, :, 2]
    det = (b[:, 1] - b[:, 0]) * (z[:, 2] - z[:, 0]) - (b[:, 2] - b[:, 0]) * (z[:, 1] - z[:, 0])
    usable = np.abs(det) > 1e-12
    b, z, a, det = b[usable], z[usable], triangles[usable][:, :, 0], det[usable]
    # a tiny fixed offset keeps the ray off shared edges and vertices
    pb, pz = point[1] + 1.234567e-7, point[2] + 2.345678e-7
    s = ((pb - b[:, 0]) * (z[:, 2] - z[:, 0]) - (b[:, 2] - b[:, 0]) * (pz - z[:, 0])) / det
    t = ((b[:, 1] - b[:, 0]) * (pz - z[:, 0]) - (pb - b[:, 0]) * (z[:, 1] - z[:, 0])) / det
    hit = (s >= 0) & (t >= 0) & (s + t <= 1)
    crossing = a[:, 0] + s * (a[:, 1] - a[:, 0]) + t * (a[:, 2] - a[:, 0])
    return bool(np.count_nonzero(hit & (crossing > point[0])) % 2)


class Bands:
    """A slab's surface cut once into height bands, so every window of heights is a union of bands.

    The sampler's windows ``[h, h + W]`` and columns ``z >= h`` all start and
    end on the given levels; cutting the slab at each level once replaces two
    cuts per window, and the extents along ``a`` of the bands give the
    window's and the column's extents without cutting at all. Within a
    b-slab the solid's extent along ``a`` equals its surface's, so these
    extents are exact intersection tests for the finger body and the descent
    column.

    Parameters
    ----------
    vertices, faces : ndarray
        The part surface clipped to a slab, ``(a, b, z)`` coordinates.
    levels : (k,) float
        Heights at which windows start or end, mm.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, levels: np.ndarray):
        self.levels = np.unique(levels)
        vertices, self.bands = cut_at_levels(vertices, faces, 2, self.levels)
        self.vertices = vertices
        self.band_areas = [triangle_areas_normals(vertices, band)[0] for band in self.bands]
        extent = np.array(
            [(vertices[band, 0].min(), vertices[band, 0].max()) if len(band) else (_INF, -_INF) for band in self.bands]
        )
        self.extent = extent
        # everything above each band's bottom, for the descent column
        self.above_min = np.minimum.accumulate(extent[::-1, 0])[::-1]
        self.above_max = np.maximum.accumulate(extent[::-1, 1])[::-1]

    def _first_band_above(self, level: float) -> int:
        """Index of the band whose bottom is ``level`` (one of the levels given)."""
        return int(np.searchsorted(self.levels, level)) + 1

    def between(self, z_low: float, z_high: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[float, float]]:
        """Surface between two levels: vertices, faces, face areas (mm²) and its extent ``(a_min, a_max)`` along
        ``a``.
        """
        first, last = self._first_band_above(z_low), self._first_band_above(z_high)
        extent = self.extent[first:last]
        faces = np.vstack(self.bands[first:last])
        areas = np.concatenate(self.band_areas[first:last])
        return self.vertices, faces, areas, (float(extent[:, 0].min()), float(extent[:, 1].max()))

    def above(self, z_low: float) -> tuple[float, float] | None:
        """Extent along ``a`` of the surface above ``z_low``, or None if there is none."""
        first = self._first_band_above(z_low)
        if first >= len(self.bands) or self.above_min[first] > self.above_max[first]:
            return None
        return float(self.above_min[first]), float(self.above_max[first])
