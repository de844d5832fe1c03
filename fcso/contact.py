"""Contact evaluation by seating the part against a fingerpad (METHOD §6)."""

from __future__ import annotations

from dataclasses import dataclass

import igl
import numpy as np

from .geometry import triangle_areas_normals


@dataclass
class SurfaceSamples:
    """Points spread uniformly by area over the part surface inside a pad box.

    Attributes
    ----------
    points : (n, 3) float
        Pad frame, mm.
    normals : (n, 3) float
        The part's outward unit normals at the points, pad frame.
    area_per_point_mm2 : float
        Surface area each point stands for.
    """

    points: np.ndarray
    normals: np.ndarray
    area_per_point_mm2: float


def sample_surface(vertices: np.ndarray, faces: np.ndarray, density_per_mm2: float, seed) -> SurfaceSamples:
    """Sample a triangle surface uniformly by area.

    Parameters
    ----------
    vertices, faces : ndarray
        The surface (mm).
    density_per_mm2 : float
        Points per mm²; the count is ``ceil(area * density)``.
    seed : int or sequence of int
        Seed of :func:`numpy.random.default_rng`, so results do not depend on
        anything but the inputs.

    Returns
    -------
    SurfaceSamples
    """
    if len(faces) == 0:
        return SurfaceSamples(np.zeros((0, 3)), np.zeros((0, 3)), 0.0)
    areas, normals = triangle_areas_normals(vertices, faces)
    total = float(areas.sum())
    if total <= 0:
        return SurfaceSamples(np.zeros((0, 3)), np.zeros((0, 3)), 0.0)
    count = int(np.ceil(total * density_per_mm2))
    rng = np.random.default_rng(seed)
    chosen = rng.choice(len(areas), size=count, p=areas / total)
    r1, r2 = rng.random(count), rng.random(count)
    flip = r1 + r2 > 1.0
    r1[flip], r2[flip] = 1.0 - r1[flip], 1.0 - r2[flip]
    triangles = vertices[faces[chosen]]
    points = (
        triangles[:, 0]
        + r1[:, None] * (triangles[:, 1] - triangles[:, 0])
        + r2[:, None] * (triangles[:, 2] - triangles[:, 0])
    )
    return SurfaceSamples(points, normals[chosen], total / count)


@dataclass
class PadContact:
    """Result of seating one pad.

    Attributes
    ----------
    offset_mm : float
        Seating offset ``t`` along ``-u``; negative when the pad advanced
        past the METHOD §6 seat to close a clearance.
    contact_area_mm2 : float
        Part surface within ``eps`` of the pad at the seated position.
    contact : (n,) bool
        Which samples are in contact.
    """

    offset_mm: float
    contact_area_mm2: float
    contact: np.ndarray


@dataclass
class PadPlacement:
    """One pad of a grasp, seated against the part (METHOD §4, §6).

    Attributes
    ----------
    frame : (4, 4) float
        Resting frame to pad frame.
    offset_mm : float
        Seating offset ``t``: the pad sits ``t`` further out along ``u``.
    samples : SurfaceSamples
        Part surface samples inside the pad box (pad frame, before seating).
    contact : (n,) bool
        Which samples touch the pad.
    """

    frame: np.ndarray
    offset_mm: float
    samples: SurfaceSamples
    contact: np.ndarray


def seat(
    samples: list[SurfaceSamples],
    pad_vertices: np.ndarray,
    pad_faces: np.ndarray,
    eps_mm: float,
    max_iterations: int = 400,
    travel_mm: float = 0.0,
) -> list[PadContact]:
    """Seat parts against one pad and find their contact (METHOD §6).

    Each part moves along ``-u`` (away from the pad) by the smallest
    ``t >= 0`` at which none of its samples lies deeper than ``eps`` inside
    the pad. Depth is Euclidean (signed distance to the pad mesh). A sample
    at depth ``δ`` needs at least ``δ - eps`` of travel before it can be
    shallow enough, so stepping ``t`` by the largest such amount never passes
    the smallest feasible ``t``; a floor of ``eps / 8`` per step bounds the
    iterations and the overshoot. Where a wall nearly parallel to ``u`` makes
    such steps crawl, the measured rate of progress is extrapolated and the
    first feasible offset found that way is bisected back to within ``eps / 8``
    of the last infeasible one.

    Then, as the gripper closes, the pad travels on toward the part until
    contact, by at most ``travel_mm`` (:func:`fcso.printfit.closing_travel_mm`:
    a pocket carved with a clearance leaves a gap to close). Each step
    advances by the smallest sample distance, which no sample can cross,
    until a sample is within ``eps / 8`` of the pad. ``travel_mm = 0``
    (no clearance) is METHOD §6 exactly.

    Parameters
    ----------
    samples : list of SurfaceSamples
        Part surfaces inside the pad box, one per pad geometry, pad frame.
    pad_vertices, pad_faces : ndarray
        The fingerpad ``P`` (pad frame, closed mesh).
    eps_mm : float
        Contact tolerance.
    travel_mm : float
        Farthest advance of the pad past the METHOD §6 seat, mm.

    Returns
    -------
    list of PadContact
        One per entry of ``samples``.
    """
    # zero-area triangles (slivers of Booleans) have no normal and would corrupt the
    # angle-weighted pseudonormals that give the distance its sign; the surface is the same
    corners = pad_vertices[pad_faces]
    doubled_area = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    pad_faces = pad_faces[doubled_area > 1e-12]
    counts = [len(s.points) for s in samples]
    everything = np.vstack([s.points for s in samples]) if sum(counts) else np.zeros((0, 3))
    # one distance query for all geometries at t = 0: most never move
    initial = np.split(_signed_distance(everything, pad_vertices, pad_faces), np.cumsum(counts)[:-1])
    return [
        _seat_one(s, d, pad_vertices, pad_faces, eps_mm, max_iterations, travel_mm) for s, d in zip(samples, initial)
    ]


def _seat_one(samples, distances, pad_vertices, pad_faces, eps_mm, max_iterations, travel_mm=0.0) -> PadContact:
    if len(samples.points) == 0:
        return PadContact(0.0, 0.0, np.zeros(0, dtype=bool))
    step_floor = eps_mm / 8.0

    def depths_at(offset: float) -> np.ndarray:
        return _signed_distance(samples.points - [offset, 0.0, 0.0], pad_vertices, pad_faces)

    # safe steps: a sample at depth d needs at least d - eps more travel, so
    # the steps never pass the smallest feasible offset; past ``limit`` every
    # sample lies below the pad, so no offset beyond it is ever needed
    limit = float(samples.points[:, 0].max() - pad_vertices[:, 0].min()) + eps_mm
    offset, infeasible = 0.0, None
    previous = None
    for _ in range(max_iterations):
        deepest = float(-distances.min())
        if deepest <= eps_mm or offset >= limit:
            break
        infeasible = offset
        step = max(deepest - eps_mm, step_floor)
        if previous is not None:
            # a wall nearly parallel to u gives way slowly: extrapolate the
            # measured rate, and bisect back below if that overshoots
            rate = (previous[0] - deepest) / previous[1]
            if 0 < rate < 0.5:
                step = max(step, (deepest - eps_mm) / rate)
        previous = (deepest, step)
        offset = min(offset + step, limit)
        distances = depths_at(offset)
    if infeasible is not None and offset - infeasible > step_floor:
        low, high, feasible = infeasible, offset, distances
        while high - low > step_floor:
            middle = (low + high) / 2.0
            trial = depths_at(middle)
            if -trial.min() <= eps_mm:
                high, feasible = middle, trial
            else:
                low = middle
        offset, distances = high, feasible
    if travel_mm > 0:
        offset, distances = _close_gap(
            samples.points, distances, offset, pad_vertices, pad_faces, eps_mm, travel_mm, max_iterations
        )
    contact = np.abs(distances) <= eps_mm
    return PadContact(offset, float(contact.sum()) * samples.area_per_point_mm2, contact)


def _close_gap(points, distances, offset, pad_vertices, pad_faces, eps_mm, travel_mm, max_iterations):
    """Advance the pad toward the part (``t`` decreasing) until contact or ``travel_mm``; returns the offset and
    distances.
    """
    limit = offset - travel_mm
    for _ in range(max_iterations):
        gap = float(distances.min())
        if gap <= eps_mm / 8.0 or offset <= limit:
            break
        offset = max(offset - gap, limit)
        distances = _signed_distance(points - [offset, 0.0, 0.0], pad_vertices, pad_faces)
    return offset, distances


def _signed_distance(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Signed distance of points to a closed mesh, negative inside (libigl AABB tree, pseudonormal sign)."""
    if len(points) == 0:
        return np.zeros(0)
    distances = igl.signed_distance(
        np.ascontiguousarray(points, dtype=np.float64),
        np.ascontiguousarray(vertices, dtype=np.float64),
        np.ascontiguousarray(faces, dtype=np.int64),
        igl.SignedDistanceType.SIGNED_DISTANCE_TYPE_PSEUDONORMAL,
    )[0]
    return np.asarray(distances)
