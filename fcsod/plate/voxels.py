"""Voxels of meshes for the placement search: the cells a solid may touch, filled, and grown by the spacing."""

from __future__ import annotations

import itertools

import numpy as np
from scipy import ndimage


def _right_triangles(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split each triangle into two right triangles along the altitude onto its longest edge.

    Parameters
    ----------
    triangles : (t, 3, 3) float

    Returns
    -------
    corner : (2t, 3) float
        The right-angle vertex (the altitude's foot).
    legs : (2t, 2, 3) float
        The two legs from ``corner``, perpendicular (either may be zero).
    bounds : (2t, 2, 3) float
        Each right triangle's bounding box.
    """
    edges = np.roll(triangles, -1, axis=1) - triangles  # edge k runs from vertex k to k + 1
    longest = np.argmax(np.einsum("tkd,tkd->tk", edges, edges), axis=1)
    rows = np.arange(len(triangles))
    b = triangles[rows, longest]
    c = triangles[rows, (longest + 1) % 3]
    a = triangles[rows, (longest + 2) % 3]
    base = c - b
    # the angles at b and c are not obtuse, so the foot lies on the longest edge
    t = np.einsum("td,td->t", a - b, base) / np.maximum(np.einsum("td,td->t", base, base), 1e-300)
    foot = b + np.clip(t, 0.0, 1.0)[:, None] * base
    corner = np.concatenate([foot, foot])
    legs = np.stack([np.concatenate([b - foot, c - foot]), np.concatenate([a - foot, a - foot])], axis=1)
    tips = np.stack([corner, corner + legs[:, 0], corner + legs[:, 1]], axis=1)
    return corner, legs, np.stack([tips.min(axis=1), tips.max(axis=1)], axis=1)


def _cell_counts(legs: np.ndarray) -> np.ndarray:
    """Cells along each leg so that a cell's box spans at most one voxel per axis.

    A cell is the parallelogram ``legs[0] / n0`` by ``legs[1] / n1``; its box
    spans ``|legs[0]| / n0 + |legs[1]| / n1`` per axis (in voxels). Of a few
    splits of that one voxel between the legs, the one with fewest cells wins.

    Returns
    -------
    (t, 2) int
    """
    # a hair larger, so that rounding cannot stretch a box past one voxel
    size = np.abs(legs) * (1.0 + 1e-9)  # (t, 2, 3)
    best = None
    for share in (0.25, 0.5, 0.75):
        first = np.maximum(np.ceil(size[:, 0].max(axis=1) / share), 1.0)
        room = 1.0 - size[:, 0] / first[:, None]  # at least 1 - share > 0
        second = np.maximum(np.ceil((size[:, 1] / room).max(axis=1)), 1.0)
        counts = np.stack([first, second], axis=1)
        if best is None:
            best = counts
        else:
            fewer = counts.prod(axis=1) < best.prod(axis=1)
            best[fewer] = counts[fewer]
    return best.astype(np.int64)


def surface_voxels(vertices: np.ndarray, faces: np.ndarray, origin: np.ndarray, voxel: float, shape) -> np.ndarray:
    """Voxels a mesh's surface may touch (a superset of those it touches).

    Each triangle is split into two right triangles, each covered by a
    lattice of parallelogram cells along its legs whose boxes span at most
    one voxel per axis (cell count about four times the area in voxels, so
    thin triangles stay cheap); every voxel a cell's box, clipped to its
    triangle's box, overlaps (at most two per axis) is marked.

    Parameters
    ----------
    vertices : (n, 3) float
        Mesh vertices, mm.
    faces : (m, 3) int
    origin : (3,) float
        Lower corner of voxel 0, mm.
    voxel : float
        Voxel edge, mm.
    shape : (3,) int
        Grid shape; the surface must lie inside the grid.

    Returns
    -------
    bool array of ``shape``
    """
    triangles = (np.asarray(vertices, dtype=np.float64)[faces] - origin) / voxel
    corner, legs, bounds = _right_triangles(triangles)
    counts = _cell_counts(legs)
    # cells (i, j) whose lower corner i / n0 + j / n1 <= 1 lies in the
    # triangle: every point of it lies in one of them
    rows_of = np.repeat(np.arange(len(corner)), counts[:, 0])
    i = np.arange(len(rows_of)) - np.repeat(np.cumsum(counts[:, 0]) - counts[:, 0], counts[:, 0])
    n0, n1 = counts[rows_of, 0], counts[rows_of, 1]
    per_row = np.minimum(n1, (n0 - i) * n1 // n0 + 1)
    cell_of = np.repeat(rows_of, per_row)
    j = np.arange(len(cell_of)) - np.repeat(np.cumsum(per_row) - per_row, per_row)
    step = legs[cell_of] / counts[cell_of][:, :, None]  # (c, 2, 3)
    start = corner[cell_of] + np.repeat(i, per_row)[:, None] * step[:, 0] + j[:, None] * step[:, 1]
    low = np.maximum(start + np.minimum(step[:, 0], 0.0) + np.minimum(step[:, 1], 0.0), bounds[cell_of, 0])
    high = np.minimum(start + np.maximum(step[:, 0], 0.0) + np.maximum(step[:, 1], 0.0), bounds[cell_of, 1])
    # the closed voxels covering each cell's box [a, b]: floor(a) to ceil(b) - 1
    low_index = np.floor(low).astype(np.int64)
    high_index = np.maximum(np.ceil(high).astype(np.int64) - 1, low_index)
    limit = np.array(shape) - 1
    low_index, high_index = np.clip(low_index, 0, limit), np.clip(high_index, 0, limit)
    grid = np.zeros(tuple(int(n) for n in shape), dtype=bool)
    flat = grid.reshape(-1)
    strides = np.array([shape[1] * shape[2], shape[2], 1], dtype=np.int64)
    for choice in itertools.product((False, True), repeat=3):
        flat[np.where(choice, high_index, low_index) @ strides] = True
    return grid


def solid_voxels(vertices: np.ndarray, faces: np.ndarray, origin: np.ndarray, voxel: float, shape) -> np.ndarray:
    """Voxels a closed mesh's solid may touch.

    The surface voxels plus every voxel they enclose (6-connected fill of the
    outside); enclosed voids count as solid.

    Parameters
    ----------
    vertices : (n, 3) float
        Mesh vertices, mm.
    faces : (m, 3) int
    origin : (3,) float
        Lower corner of voxel 0, mm.
    voxel : float
        Voxel edge, mm.
    shape : (3,) int
        Grid shape, with at least one empty voxel around the mesh.

    Returns
    -------
    bool array of ``shape``
    """
    return ndimage.binary_fill_holes(surface_voxels(vertices, faces, origin, voxel, shape))


def grow(solid: np.ndarray, voxel: float, clearance_mm: float) -> np.ndarray:
    """Voxels whose cube comes closer than ``clearance_mm`` to a cube of ``solid``.

    Cubes ``d`` voxels apart are ``voxel * |max(|d| - 1, 0)|`` apart: a
    Euclidean distance transform below the clearance, then a 3 x 3 x 3
    dilation. ``solid`` needs ``ceil(clearance_mm / voxel) + 1`` empty voxels
    around its content.

    Returns
    -------
    bool array like ``solid``; ``solid`` itself when the clearance is 0.
    """
    if clearance_mm <= 0 or not solid.any():
        return solid.copy()
    near = ndimage.distance_transform_edt(~solid) * voxel < clearance_mm
    return ndimage.binary_dilation(near, structure=np.ones((3, 3, 3), dtype=bool))


def mark_pad(voxel: float, clearance_mm: float) -> int:
    """Voxels around a solid's voxels that :func:`grow` needs (plus one for the fill)."""
    return int(np.ceil(clearance_mm / voxel)) + 2
