"""The ``(v, w)`` grid of cells over the pad face, and a surface's column heights on it (the screening's maps,
:mod:`fcso.screen`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .config import DesignConfig

#: Grid cell of the column heights, in units of the contact tolerance eps.
CELL_PER_EPS = 4.0


@dataclass
class ScreenGrid:
    """The ``(v, w)`` grid of column heights over the pad face.

    Attributes
    ----------
    cell_mm : float
        Cell size, mm.
    count_v, count_w : int
        Cells along the pad length L and width W.
    """

    cell_mm: float
    count_v: int
    count_w: int

    @classmethod
    def for_config(cls, config: DesignConfig) -> ScreenGrid:
        """The grid for a design's pad size and contact tolerance (cell = 4 eps)."""
        cell = CELL_PER_EPS * config.contact.eps_mm
        return cls(
            cell,
            max(1, int(np.ceil(config.sampler.length_mm / cell))),
            max(1, int(np.ceil(config.sampler.width_mm / cell))),
        )

    def cells(self, v: np.ndarray, w: np.ndarray) -> np.ndarray:
        """Flat cell index of points at ``(v, w)`` (mm), clipped to the grid."""
        j = np.clip((np.asarray(v) / self.cell_mm).astype(np.int64), 0, self.count_v - 1)
        k = np.clip((np.asarray(w) / self.cell_mm).astype(np.int64), 0, self.count_w - 1)
        return (j * self.count_w + k).astype(np.int32)


def column_heights(vertices: np.ndarray, faces: np.ndarray, grid: ScreenGrid) -> np.ndarray:
    """Top ``u`` of a surface along the ``u`` ray through every cell centre.

    Parameters
    ----------
    vertices, faces : ndarray
        The part surface inside the pad box, pad frame ``(u, v, w)``, mm.
    grid : ScreenGrid

    Returns
    -------
    (count_v * count_w,) float32
        Largest ``u`` hit on each ray, mm; 0 where no triangle covers the cell centre.

    Each triangle is scanned row by row of cell centres: the row's line
    crosses the triangle's projection in one interval of ``w``, and every
    centre in it takes the height of the triangle's plane there, so only
    covered cells are visited.
    """
    heights = np.zeros(grid.count_v * grid.count_w, dtype=np.float64)
    if len(faces) == 0:
        return heights.astype(np.float32)
    triangles = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]
    u, v, w = triangles[:, :, 0], triangles[:, :, 1], triangles[:, :, 2]
    det = (v[:, 1] - v[:, 0]) * (w[:, 2] - w[:, 0]) - (v[:, 2] - v[:, 0]) * (w[:, 1] - w[:, 0])
    # vertical triangles (in projection) cover no cell centre of their own
    keep = np.abs(det) >= 1e-12
    u, v, w, det = u[keep], v[keep], w[keep], det[keep]
    cell = grid.cell_mm
    row_first = np.clip(np.ceil(v.min(1) / cell - 0.5), 0, grid.count_v).astype(np.int64)
    row_last = np.clip(np.floor(v.max(1) / cell - 0.5), -1, grid.count_v - 1).astype(np.int64)
    rows = np.maximum(row_last - row_first + 1, 0)
    if rows.sum() == 0:
        return heights.astype(np.float32)
    # the triangle's plane u = alpha + beta v + gamma w
    du1, du2 = u[:, 1] - u[:, 0], u[:, 2] - u[:, 0]
    dv1, dv2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    dw1, dw2 = w[:, 1] - w[:, 0], w[:, 2] - w[:, 0]
    beta = (du1 * dw2 - du2 * dw1) / det
    gamma = (dv1 * du2 - dv2 * du1) / det
    alpha = u[:, 0] - beta * v[:, 0] - gamma * w[:, 0]
    # one entry per (triangle, row of cell centres it spans): the row's w-interval inside the triangle
    owner = np.repeat(np.arange(len(u)), rows)
    row = row_first[owner] + (np.arange(len(owner)) - np.repeat(np.cumsum(rows) - rows, rows))
    pv = (row + 0.5) * cell
    ev, ew = v[owner], w[owner]
    low, high = np.full(len(owner), np.inf), np.full(len(owner), -np.inf)
    for a, b in ((0, 1), (1, 2), (2, 0)):
        va, vb, wa, wb = ev[:, a], ev[:, b], ew[:, a], ew[:, b]
        span = vb - va
        crosses = (np.minimum(va, vb) <= pv) & (pv <= np.maximum(va, vb)) & (span != 0.0)
        t = np.where(crosses, (pv - va) / np.where(span != 0.0, span, 1.0), 0.0)
        crossing_w = wa + t * (wb - wa)
        low = np.where(crosses, np.minimum(low, crossing_w), low)
        high = np.where(crosses, np.maximum(high, crossing_w), high)
    first = np.clip(np.ceil((low - 1e-9) / cell - 0.5), 0, grid.count_w).astype(np.int64)
    last = np.clip(np.floor((high + 1e-9) / cell - 0.5), -1, grid.count_w - 1).astype(np.int64)
    cells = np.maximum(last - first + 1, 0)
    entry = np.repeat(np.arange(len(owner)), cells)
    if len(entry) == 0:
        return heights.astype(np.float32)
    column = first[entry] + (np.arange(len(entry)) - np.repeat(np.cumsum(cells) - cells, cells))
    triangle = owner[entry]
    top = alpha[triangle] + beta[triangle] * pv[entry] + gamma[triangle] * ((column + 0.5) * cell)
    np.maximum.at(heights, row[entry] * grid.count_w + column, top)
    return heights.astype(np.float32)
