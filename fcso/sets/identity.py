"""Identical parts of a job, found by geometry so they are designed once (METHOD §11)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import trimesh
from scipy.spatial import cKDTree

#: Largest distance between matching vertices of identical parts, mm (STL stores float32: ~1e-5 mm at 100 mm).
SAME_GEOMETRY_TOLERANCE_MM = 1e-3


def same_geometry(a: trimesh.Trimesh, b: trimesh.Trimesh, tolerance_mm: float = SAME_GEOMETRY_TOLERANCE_MM) -> bool:
    """Whether two parts have the same geometry up to a translation.

    Parameters
    ----------
    a, b : trimesh.Trimesh
        Parts in mm, after units and shell union (:func:`fcso.load_parts`).
    tolerance_mm : float
        Every vertex of each, moved so the bounding boxes' minimum corners
        meet, lies within this distance of a vertex of the other.

    Returns
    -------
    bool
        Equal face counts, volumes within 10⁻⁶ relative and matching vertices.
        Rotated copies are not the same: they rest differently and are
        designed as parts of their own.
    """
    if len(a.faces) != len(b.faces) or len(a.vertices) != len(b.vertices):
        return False
    if not np.isclose(a.volume, b.volume, rtol=1e-6, atol=1e-6):
        return False
    va = np.asarray(a.vertices) - np.asarray(a.vertices).min(axis=0)
    vb = np.asarray(b.vertices) - np.asarray(b.vertices).min(axis=0)
    return bool(cKDTree(vb).query(va)[0].max() <= tolerance_mm and cKDTree(va).query(vb)[0].max() <= tolerance_mm)


def identical_groups(meshes: Sequence[trimesh.Trimesh]) -> list[list[int]]:
    """Indices of the meshes grouped by :func:`same_geometry`, groups and members in input order."""
    groups: list[list[int]] = []
    for index, mesh in enumerate(meshes):
        group = next((g for g in groups if same_geometry(meshes[g[0]], mesh)), None)
        if group is None:
            groups.append([index])
        else:
            group.append(index)
    return groups
