"""The pad's face heights as printed, on the screening grid (METHOD §8b, §9b).

:mod:`fcso.printfit` carves a drafted pocket as the part moved ``c``
deeper with its walls drafted by the lead-in (METHOD §9c), and an undrafted
one as the part grown by a ball of radius ``c``; this is the same on column
heights: ``+ c``, or a grey dilation by a hemisphere, then every wall
drafted, ``H(x) = max_y H(y) - |x - y| cot α`` (wider at the pad face,
exact at depth). The capture model (:mod:`fcso.capture`) squeezes parts between
these heights.
"""

from __future__ import annotations

import numpy as np

from .grid import ScreenGrid
from .jit import compiled
from .screen import ScreenGeometry


def carved_heights(geometries: list[ScreenGeometry], grid: ScreenGrid) -> np.ndarray:
    """Largest column height of the good geometries, ``(count_v, count_w)`` mm; ``-inf`` where none carves."""
    carved = np.full((grid.count_v, grid.count_w), -np.inf)
    for geometry in geometries:
        if geometry.good:
            # outside its window a geometry's heights are 0: it carves nothing there
            heights = geometry.window_heights_mm
            np.maximum(carved[geometry.cells], np.where(heights > 0, heights, -np.inf), out=carved[geometry.cells])
    return carved


def fitted_pad_heights(
    carved_mm: np.ndarray, floor_mm: float, cell_mm: float, clearance_mm: float, lead_in_deg: float
) -> np.ndarray:
    """The pad's face heights ``P = {u >= H}`` as printed.

    Parameters
    ----------
    carved_mm : (count_v, count_w) float
        Largest column height of the carved (good) geometries, mm; ``-inf``
        where none carves.
    floor_mm : float
        The pad face where nothing is carved (0, the block's ``D - d_B``, or
        ``D`` for a flat pad), mm.
    cell_mm : float
        Grid cell, mm.
    clearance_mm, lead_in_deg : float
        ``[print]``'s fit; 0 and 0 give the exact pocket.

    Returns
    -------
    (count_v, count_w) float
    """
    cleared = clearance_heights(carved_mm, cell_mm, clearance_mm, drafted=lead_in_deg > 0)
    return drafted_heights(cleared, floor_mm, cell_mm, lead_in_deg)


def clearance_heights(carved_mm: np.ndarray, cell_mm: float, clearance_mm: float, drafted: bool) -> np.ndarray:
    """The carved heights given the clearance, before any draft: ``c`` deeper for a pocket that will be drafted
    (METHOD §9c, as :func:`fcso.printfit.carve`), else grown by a ball of radius ``c``; mm, as ``carved_mm``."""
    heights = np.asarray(carved_mm, dtype=np.float64).copy()
    if clearance_mm <= 0 or not np.isfinite(heights).any():
        return heights
    if drafted:
        return heights + clearance_mm
    # grey dilation by a hemisphere, so pocket edges are rounded as carved
    radius = int(np.ceil(clearance_mm / cell_mm - 1e-9))
    padded = np.pad(heights, radius, constant_values=-np.inf)
    grown = np.full_like(heights, -np.inf)
    count_v, count_w = heights.shape
    for dv in range(-radius, radius + 1):
        for dw in range(-radius, radius + 1):
            lateral = np.hypot(dv, dw) * cell_mm
            if lateral <= clearance_mm + 1e-9:
                window = padded[radius + dv : radius + dv + count_v, radius + dw : radius + dw + count_w]
                np.maximum(grown, window + np.sqrt(clearance_mm**2 - min(lateral, clearance_mm) ** 2), out=grown)
    return grown


def drafted_heights(heights_mm: np.ndarray, floor_mm: float, cell_mm: float, lead_in_deg: float) -> np.ndarray:
    """Heights (:func:`clearance_heights`) with every wall drafted by ``lead_in_deg`` and raised to the floor, mm."""
    heights = np.asarray(heights_mm, dtype=np.float64)
    if lead_in_deg > 0 and np.isfinite(heights).any():
        # raised to the floor first: the draft then stops where it meets the floor, a few cells
        # out, instead of spreading below it over the whole grid (the same result, ~30x fewer passes)
        heights = np.maximum(heights, floor_mm)
        drop = cell_mm / np.tan(np.radians(lead_in_deg))
        heights = _drafted(heights, float(drop), float(drop * np.sqrt(2.0)))
    return np.maximum(heights, floor_mm)


@compiled("(float64[:, ::1], float64, float64)")
def _drafted(heights, drop, diagonal):
    """Every wall of ``heights`` drafted: ``H = max(H, max of the 4 side neighbours - drop, max of the 4 corner
    neighbours - diagonal)`` at every cell until none changes.

    In place, in sweeps that alternate between the grid's two diagonal orders, so a draft runs down a whole wall
    in one sweep (passes over a copy moved it one cell per pass: a 4 mm pocket at a 15-degree draft is 60 passes of
    a 0.25 mm grid). Each height reached is the largest over paths from a cell of ``heights`` of its height less
    each step's drop, taken in order, whichever order the cells are visited in: the least heights above
    ``heights`` that no step raises, bit for bit those of the passes over a copy. At most ``2 (count_v +
    count_w)`` sweeps.
    """
    rows, columns = heights.shape
    current = heights.copy()
    for sweep in range(2 * (rows + columns)):
        changed = False
        backward = sweep % 2 == 1
        for r in range(rows):
            i = rows - 1 - r if backward else r
            for c in range(columns):
                j = columns - 1 - c if backward else c
                straight, corner = -np.inf, -np.inf
                if i > 0:
                    straight = max(straight, current[i - 1, j])
                    if j > 0:
                        corner = max(corner, current[i - 1, j - 1])
                    if j + 1 < columns:
                        corner = max(corner, current[i - 1, j + 1])
                if i + 1 < rows:
                    straight = max(straight, current[i + 1, j])
                    if j > 0:
                        corner = max(corner, current[i + 1, j - 1])
                    if j + 1 < columns:
                        corner = max(corner, current[i + 1, j + 1])
                if j > 0:
                    straight = max(straight, current[i, j - 1])
                if j + 1 < columns:
                    straight = max(straight, current[i, j + 1])
                value = max(current[i, j], max(straight - drop, corner - diagonal))
                if value != current[i, j]:
                    current[i, j] = value
                    changed = True
        if not changed:
            break
    return current
