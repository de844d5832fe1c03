"""Contact evaluation by seating the part against a fingerpad (METHOD §6)."""

from __future__ import annotations

from dataclasses import dataclass

import igl
import numpy as np

from .config import DesignConfig
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
    seatings = [
        _seat_one(s, d, float(pad_vertices[:, 0].min()), eps_mm, max_iterations, travel_mm)
        for s, d in zip(samples, initial)
    ]
    return _run_together(seatings, pad_vertices, pad_faces)


def _run_together(seatings: list, pad_vertices: np.ndarray, pad_faces: np.ndarray) -> list[PadContact]:
    """Drive every geometry's seating in lockstep: each round answers all their distance queries in one libigl call.

    A libigl query builds its tree over the pad each time; one query per round instead of one per geometry and step
    spares that, and every point's distance is the same as asked alone.
    """
    results: list[PadContact | None] = [None] * len(seatings)
    asked: dict[int, np.ndarray] = {}
    for number, seating in enumerate(seatings):
        _advance(seating, number, None, asked, results)
    while asked:
        numbers = list(asked)
        counts = [len(asked[n]) for n in numbers]
        answers = np.split(
            _signed_distance(np.vstack([asked[n] for n in numbers]), pad_vertices, pad_faces), np.cumsum(counts)[:-1]
        )
        asked = {}
        for number, answer in zip(numbers, answers):
            _advance(seatings[number], number, answer, asked, results)
    return results


def _advance(seating, number: int, answer: np.ndarray | None, asked: dict, results: list) -> None:
    """Send a seating its distances; record its next query in ``asked``, or its contact in ``results`` once done."""
    try:
        asked[number] = seating.send(answer)
    except StopIteration as done:
        results[number] = done.value


#: Points farther than this beyond the contact tolerance are left out of a seating's later distance queries, mm.
_FAR_MARGIN_MM = 1.0


def _seat_one(samples, distances, pad_min_u_mm, eps_mm, max_iterations, travel_mm=0.0):
    """One geometry's seating (METHOD §6), a generator: it yields the points it needs the signed distances of and
    returns its PadContact.

    A signed distance changes by at most the distance a point moves, so a point farther than
    ``eps + _FAR_MARGIN_MM`` from the pad, by the last distance it was measured at less the travel since, can neither
    be the deepest nor touch: it is not queried again (closing a gap, which needs the nearest point, queries all).
    """
    if len(samples.points) == 0:
        return PadContact(0.0, 0.0, np.zeros(0, dtype=bool))
    step_floor = eps_mm / 8.0
    points = samples.points
    measured = distances.copy()  # every point's distance where it was last measured
    measured_at = np.zeros(len(points))  # the offset it was last measured at

    def query(offset: float):
        """The distances at ``offset``: near points measured, far ones ``inf`` (they cannot touch)."""
        near = np.flatnonzero(measured - np.abs(offset - measured_at) <= eps_mm + _FAR_MARGIN_MM)
        found = yield points[near] - [offset, 0.0, 0.0]
        measured[near], measured_at[near] = found, offset
        result = np.full(len(points), np.inf)
        result[near] = found
        return result

    # safe steps: a sample at depth d needs at least d - eps more travel, so
    # the steps never pass the smallest feasible offset; past ``limit`` every
    # sample lies below the pad, so no offset beyond it is ever needed
    limit = float(points[:, 0].max() - pad_min_u_mm) + eps_mm
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
        distances = yield from query(offset)
    if infeasible is not None and offset - infeasible > step_floor:
        low, high, feasible = infeasible, offset, distances
        while high - low > step_floor:
            middle = (low + high) / 2.0
            trial = yield from query(middle)
            if -trial.min() <= eps_mm:
                high, feasible = middle, trial
            else:
                low = middle
        offset, distances = high, feasible
    if travel_mm > 0:
        # close the gap: advance the pad toward the part (t decreasing) until contact or travel_mm
        closest = offset - travel_mm
        if np.isinf(distances).any():
            distances = yield points - [offset, 0.0, 0.0]
        for _ in range(max_iterations):
            gap = float(distances.min())
            if gap <= eps_mm / 8.0 or offset <= closest:
                break
            offset = max(offset - gap, closest)
            distances = yield points - [offset, 0.0, 0.0]
    contact = np.abs(distances) <= eps_mm
    return PadContact(offset, float(contact.sum()) * samples.area_per_point_mm2, contact)


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


def contact_seed(config: DesignConfig, scenario_number: int, sample_index: int, side_number: int) -> tuple[int, ...]:
    """The seed of one pad geometry's contact samples: ``(contact.seed, scenario, sample, side)``.

    So a report can be rebuilt with exactly the samples the design used.

    Parameters
    ----------
    config : DesignConfig
    scenario_number, sample_index, side_number : int
        Position of the scenario in the design, of the sample in the scenario,
        and the side (0: "+", 1: "-").
    """
    return (config.contact.seed, scenario_number, sample_index, side_number)


def contact_samples(
    vertices: np.ndarray,
    faces: np.ndarray,
    config: DesignConfig,
    scenario_number: int,
    sample_index: int,
    side_number: int,
) -> SurfaceSamples:
    """The design's surface samples of one pad geometry (seeded by :func:`contact_seed`).

    Parameters
    ----------
    vertices, faces : ndarray
        Part surface inside the pad box, pad frame (:func:`fcso.pad.surface_in_pad`).
    config : DesignConfig
    scenario_number, sample_index, side_number : int
        As for :func:`contact_seed`.
    """
    seed = list(contact_seed(config, scenario_number, sample_index, side_number))
    return sample_surface(vertices, faces, config.contact.sample_density_per_mm2, seed)
