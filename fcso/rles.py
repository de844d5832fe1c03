"""RLES grasp quality: the exact largest empty spherical cap among contact normals.

``max_c min_i |c - n_i|`` over unit ``c`` is evaluated with a KD-tree at a
finite candidate set that contains the maximiser: the spherical Voronoi
vertices (convex-hull facet normals, or the poles of the plane of cocircular
normals), the edge points ``-(n_i + n_j)/|n_i + n_j|`` of Voronoi neighbours,
and ``-n`` for a single normal.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError, cKDTree

#: Rows shorter than this (any unit) are not normals and are dropped.
MIN_NORM = 1e-12
#: Unit normals equal after rounding to this many decimals are duplicates.
DEDUP_DECIMALS = 9
#: Normals within this distance of one plane are treated as cocircular.
PLANE_TOLERANCE = 1e-9

_TINY = 1e-12
#: Candidates with the largest upper bounds evaluated first.
_FIRST_QUERIES = 16
#: Slack of the test that an edge point lies between its two Voronoi vertices.
_CONE_TOLERANCE = 1e-9


def fibonacci_sphere(count: int) -> np.ndarray:
    """Nearly uniform unit vectors on the sphere (Fibonacci lattice).

    Parameters
    ----------
    count : int
        Number of points, ``>= 0``.

    Returns
    -------
    points : (count, 3) float ndarray
        Unit vectors; point ``k`` has height ``z = 1 - (2k + 1) / count`` and
        azimuth ``k`` times the golden angle. The largest distance from any
        point of the sphere to its nearest lattice point is
        about ``0.75 * sqrt(4 pi / count)`` (measured).
    """
    count = int(count)
    if count < 0:
        raise ValueError(f"count must be >= 0, got {count}")
    k = np.arange(count, dtype=np.float64)
    z = 1.0 - (2.0 * k + 1.0) / max(count, 1)
    radius = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
    azimuth = k * (np.pi * (3.0 - np.sqrt(5.0)))
    return np.column_stack((radius * np.cos(azimuth), radius * np.sin(azimuth), z))


def rles(normals) -> float:
    """Radius of the largest empty sphere (cap) among contact normals.

    Parameters
    ----------
    normals : (N, 3) array_like of float
        Contact normals; any length (rows are normalised, rows with norm
        below `MIN_NORM` are dropped). Duplicates are allowed.

    Returns
    -------
    rles : float
        ``max_c min_i |c - n_i|`` over unit vectors ``c``: the chord distance
        (unit sphere, dimensionless) from the most isolated point of the
        sphere to its nearest normal, in [0, 2]. 2.0 for no or a single
        distinct normal, ``sqrt(2)`` for two antipodal normals (flat pads).
        Smaller is better: the normals cover the sphere more evenly.

    See Also
    --------
    largest_empty_cap : the same value and the centre of the cap.
    """
    return largest_empty_cap(normals)[0]


def largest_empty_cap(normals) -> tuple[float, np.ndarray]:
    """The largest spherical cap containing no contact normal, exactly.

    Parameters
    ----------
    normals : (N, 3) array_like of float
        Contact normals; any length (rows are normalised, rows with norm
        below `MIN_NORM` are dropped). Duplicates are allowed.

    Returns
    -------
    rles : float
        Chord radius of the cap, in [0, 2] (see `rles`).
    centre : (3,) float ndarray
        Unit vector at the centre of the cap; its distance to the nearest
        normal is `rles`. When the maximiser is not unique (e.g. no normals,
        two antipodal normals) one of them is returned.

    Raises
    ------
    ValueError
        If `normals` is not (N, 3) or holds non-finite values.
    """
    points = _unique_unit_normals(normals)
    if len(points) == 0:
        return 2.0, np.array([0.0, 0.0, 1.0])
    if len(points) == 1:
        return 2.0, -points[0]
    candidates, anchors = _candidates(points)
    value, best = _max_nearest_distance(points, candidates, anchors)
    return float(np.clip(value, 0.0, 2.0)), candidates[best].copy()


def _max_nearest_distance(points: np.ndarray, candidates: np.ndarray, anchors: np.ndarray) -> tuple[float, int]:
    """``max_k min_i |candidates[k] - points[i]|`` and its ``k``, exactly.

    ``|candidates[k] - points[anchors[k]]|`` bounds the nearest distance of
    candidate ``k`` from above, so candidates are evaluated with the KD-tree
    in decreasing order of that bound and those whose bound cannot beat the
    best value found are skipped (they cannot be the maximum).
    """
    bound = np.linalg.norm(candidates - points[anchors], axis=1)
    order = np.argsort(-bound, kind="stable")
    tree = cKDTree(points)
    head = order[:_FIRST_QUERIES]
    distances, _ = tree.query(candidates[head])
    best = int(np.argmax(distances))
    value, index = float(distances[best]), int(head[best])
    rest = order[_FIRST_QUERIES:]
    rest = rest[bound[rest] > value]
    if len(rest):
        distances, _ = tree.query(candidates[rest])
        best = int(np.argmax(distances))
        if distances[best] > value:
            value, index = float(distances[best]), int(rest[best])
    return value, index


def _unique_unit_normals(normals) -> np.ndarray:
    """Unit-length, finite, deduplicated normals, in first-occurrence order."""
    array = np.asarray(normals, dtype=np.float64)
    if array.size == 0:
        return np.empty((0, 3))
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"normals must have shape (N, 3), got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError("normals must be finite")
    lengths = np.linalg.norm(array, axis=1)
    keep = lengths >= MIN_NORM
    unit = array[keep] / lengths[keep, None]
    if len(unit) < 2:
        return unit
    # duplicates: equal after rounding to DEDUP_DECIMALS (integer keys, no -0.0)
    key = np.rint(unit * 10.0**DEDUP_DECIMALS).astype(np.int64)
    order = np.lexsort(key.T[::-1])
    sorted_key = key[order]
    new = np.ones(len(key), dtype=bool)
    new[1:] = (sorted_key[1:] != sorted_key[:-1]).any(axis=1)
    # first occurrence of each key: lexsort is stable
    return unit[np.sort(order[new])]


def _candidates(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors containing the maximiser of ``min_i |c - n_i|`` (n >= 2).

    Returns the candidates and, for each, the index of a normal that is
    nearest to it when the candidate is a true Voronoi vertex or edge point
    (used only as an upper bound).
    """
    if len(points) == 2:
        return _cocircular_candidates(points, _two_point_pole(points[0], points[1]))
    centred = points - points.mean(axis=0)
    axis = np.linalg.svd(centred, full_matrices=False)[2][-1]
    if np.max(np.abs(centred @ axis)) <= PLANE_TOLERANCE:
        return _cocircular_candidates(points, axis)
    return _hull_candidates(points)


def _two_point_pole(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pole of the great circle through ``a`` and ``b`` (any, if antipodal)."""
    pole = np.cross(a, b)
    length = np.linalg.norm(pole)
    return pole / length if length > _TINY else _perpendicular(a)


def _perpendicular(vector: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to the unit vector ``vector``."""
    other = np.zeros(3)
    other[np.argmin(np.abs(vector))] = 1.0
    result = np.cross(vector, other)
    return result / np.linalg.norm(result)


def _cocircular_candidates(points: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Candidates when all normals lie in one plane with unit normal ``axis``.

    The Voronoi cells are lunes meeting at the poles ``±axis``; the edge
    between angular neighbours ``i, j`` is a half great circle from pole to
    pole, on which ``f`` is largest at a pole or at ``-(n_i+n_j)/|n_i+n_j|``
    (inside the edge when the gap between them is at least 180 degrees).
    Both arc midpoints ``±(n_i+n_j)/|.|`` are included. For an antipodal pair
    ``f`` is constant (``sqrt(2)``) on its edge, so the poles cover it.
    """
    first = _perpendicular(axis)
    second = np.cross(axis, first)
    ring = np.argsort(np.arctan2(points @ second, points @ first))
    sums = points[ring] + points[np.roll(ring, -1)]
    lengths = np.linalg.norm(sums, axis=1)
    keep = lengths > _TINY
    midpoints = sums[keep] / lengths[keep, None]
    candidates = np.vstack((axis, -axis, midpoints, -midpoints))
    anchors = np.concatenate(([0, 0], ring[keep], ring[keep]))
    return candidates, anchors


def _hull_candidates(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Candidates for >= 4 normals not in one plane.

    The spherical Voronoi vertices are the outward unit normals of the convex
    hull facets, the centres of the empty caps cut off by the facet planes
    (this is how `scipy.spatial.SphericalVoronoi` computes them); Voronoi
    neighbours ``i, j`` are hull edges, and their Voronoi edge is the arc
    between the normals ``v_f, v_g`` of the two facets sharing the hull edge.
    ``c = -(n_i+n_j)/|.|`` is kept when it lies in that arc (the normal cone
    of the hull edge, with a tolerance so the set stays a superset): only
    then can it be the maximiser. No edge can hold it when the origin is
    strictly inside the hull (``f < sqrt(2)`` everywhere, ``f(c) > sqrt(2)``).
    For an antipodal pair ``f`` is constant on its edge and the edge's
    Voronoi vertices cover it.
    """
    try:
        hull = ConvexHull(points)
    except QhullError:  # nearly flat beyond PLANE_TOLERANCE: joggle
        hull = ConvexHull(points, qhull_options="QJ")
    simplices = hull.simplices
    vertices = hull.equations[:, :3]
    vertices = vertices / np.linalg.norm(vertices, axis=1)[:, None]
    candidates, anchors = vertices, simplices[:, 0]
    if not np.all(hull.equations[:, 3] < -_TINY):  # origin not strictly inside
        facet = np.repeat(np.arange(len(simplices)), 3)
        opposite = np.tile(np.arange(3), len(simplices))
        other = hull.neighbors[facet, opposite]
        once = facet < other  # each hull edge is seen from both facets
        facet, opposite, other = facet[once], opposite[once], other[once]
        first = simplices[facet, (opposite + 1) % 3]
        second = simplices[facet, (opposite + 2) % 3]
        sums = points[first] + points[second]
        lengths = np.linalg.norm(sums, axis=1)
        keep = lengths > _TINY
        centre = -sums[keep] / lengths[keep, None]
        v_f, v_g = vertices[facet[keep]], vertices[other[keep]]
        span = np.cross(v_f, v_g)
        inside = (np.einsum("ij,ij->i", np.cross(v_f, centre), span) >= -_CONE_TOLERANCE) & (
            np.einsum("ij,ij->i", np.cross(centre, v_g), span) >= -_CONE_TOLERANCE
        )
        candidates = np.vstack((vertices, centre[inside]))
        anchors = np.concatenate((anchors, first[keep][inside]))
    finite = np.isfinite(candidates).all(axis=1)
    return candidates[finite], anchors[finite]
