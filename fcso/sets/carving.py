"""Which parts carve alike: a part's carving as a descriptor, the most dissimilar parts and each part's nearest, so a
job of many parts screens the pairs likeliest to conflict, not every pair (:mod:`fcso.sets.partition`)."""

from __future__ import annotations

import numpy as np

from .screening import SetScreener


def carving_descriptors(screener: SetScreener) -> np.ndarray:
    """What each part carves into a pad, cheaply: the column heights of its scenarios' best samples.

    Per part, the largest column height (:attr:`fcso.screen.ScreenGeometry.heights_mm`) over the good
    geometries (METHOD §5, the ones carved into the pad) of each scenario's sample of best solo screened E, on
    the pad-face grid; 0 where it carves nothing. Two parts whose carvings differ little leave each other's
    contacts nearly as they are; a part that carves deep where another touches takes that contact away.

    Returns
    -------
    (parts, cells) float64
        Heights, mm.
    """
    prepared, picks = screener.prepared, screener.picks
    rows = []
    for numbers in screener.part_scenarios:
        carving = None
        for m in numbers:
            for geometry in prepared.scenarios[m].samples[picks[m]].screen:
                heights = geometry.heights_mm if geometry.good else np.zeros_like(geometry.heights_mm)
                carving = heights if carving is None else np.maximum(carving, heights)
        rows.append(carving)
    return np.asarray(rows, dtype=np.float64)


def farthest_point_order(descriptors: np.ndarray, count: int) -> list[int]:
    """The ``count`` most dissimilar parts, in order: first the one farthest from the mean, then each the farthest
    from those already taken (ties: the smaller index). O(parts x count) distances."""
    parts = len(descriptors)
    centre = descriptors.mean(axis=0)
    nearest = np.linalg.norm(descriptors - centre, axis=1)
    order: list[int] = []
    for _ in range(min(count, parts)):
        candidates = np.where(np.isin(np.arange(parts), order), -np.inf, nearest)
        chosen = int(np.argmax(candidates))
        order.append(chosen)
        nearest = np.minimum(nearest, np.linalg.norm(descriptors - descriptors[chosen], axis=1))
    return order


def nearest_neighbour_pairs(descriptors: np.ndarray, neighbours: int) -> set[tuple[int, int]]:
    """Every part with its ``neighbours`` nearest by descriptor (ties: the smaller index), as ordered pairs."""
    squared = (descriptors**2).sum(axis=1)
    distances = squared[:, None] + squared[None, :] - 2.0 * descriptors @ descriptors.T
    np.fill_diagonal(distances, np.inf)
    nearest = np.argsort(distances, axis=1, kind="stable")[:, : min(neighbours, len(descriptors) - 1)]
    return {(min(i, int(j)), max(i, int(j))) for i in range(len(descriptors)) for j in nearest[i]}
