"""Steepest descent of a capture landscape's jaw separation (METHOD §7b): where closing the jaws takes the part from
every start error (:func:`fcso.capture.squeeze`)."""

from __future__ import annotations

import numpy as np

from .jit import compiled

#: A turn of one yaw step is taken only when it lowers the separation by more than this, mm: less is the facets of a
#: tessellated round (a 96-gon of radius 15 mm turned half a facet: 8 µm), which no grip resolves (the contacts give
#: 0.1-0.25 mm under 60 N), and which made a cylinder in its round pocket capture every start yaw.
TURN_RESOLUTION_MM = 0.02


def descent(separation: np.ndarray, step_mm: float, turn_mm: float, friction: float) -> np.ndarray:
    """Where steepest descent of ``separation`` ((rows, columns) float, mm) ends from every node (flat indices).

    A move to one of the eight neighbours is taken when its drop exceeds
    what friction holds back: a slide along the pads must drop ``s`` by
    more than ``2 μ`` per mm (two jaws), a turn only needs to drop it by
    more than :data:`TURN_RESOLUTION_MM`, since the part pivots about a contact instead of sliding along it
    (measured: friction-gated turns left the zig-zag L-part and the hex
    prism at captures of 0.19 and 0.62 where the simulation seats 10/10).
    Among the moves taken the steepest (drop per length) wins.
    """
    successor = _steepest_moves(separation, step_mm, turn_mm, friction)
    successor = successor.ravel()
    # pointer jumping: separation falls along every move, so the chains end
    for _ in range(int(np.ceil(np.log2(separation.size))) + 1):
        successor = successor[successor]
    return successor


@compiled("(float64[:, ::1], float64, float64, float64)")
def _steepest_moves(separation, step_mm, turn_mm, friction):
    """Each node's steepest move of :func:`descent` (its own flat index where none is taken)."""
    rows, columns = separation.shape
    best_slope = np.zeros(separation.shape)
    successor = np.arange(separation.size).reshape(rows, columns)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            if dr == 0 and dc == 0:
                continue
            length = np.hypot(dr * step_mm, dc * turn_mm)
            held_below = 2.0 * friction * abs(dr) * step_mm + TURN_RESOLUTION_MM * abs(dc) + 1e-9
            for r in range(rows):
                for c in range(columns):
                    inside = 0 <= r + dr < rows and 0 <= c + dc < columns
                    neighbour = separation[r + dr, c + dc] if inside else np.inf
                    drop = separation[r, c] - neighbour
                    slope = drop / length
                    if np.isfinite(slope) and not drop <= held_below and slope > best_slope[r, c]:
                        best_slope[r, c] = slope
                        successor[r, c] = (r + dr) * columns + c + dc
    return successor
