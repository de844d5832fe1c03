"""Fewer triangles for the screen: vertex clustering of a mesh for the pictures and the 3D view.

Apart from :mod:`fcso.output.render` because the 3D view of a page decimates
too, in the process that writes the page, which never loads matplotlib.
"""

from __future__ import annotations

import numpy as np

from ..geometry import triangle_areas_normals

#: Most triangles drawn per mesh in a picture; more are decimated for drawing.
MAX_DRAWN_FACES = 6000


def decimate(
    vertices: np.ndarray, faces: np.ndarray, max_faces: int = MAX_DRAWN_FACES
) -> tuple[np.ndarray, np.ndarray]:
    """Fewer triangles for drawing, by vertex clustering on a grid.

    Vertices in one grid cell merge into their mean; triangles that collapse
    or repeat are dropped. The cell grows until at most ``max_faces`` remain.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int
    max_faces : int

    Returns
    -------
    vertices, faces : ndarray
        The input itself when it is small enough.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if len(faces) <= max_faces:
        return vertices, faces
    area = float(triangle_areas_normals(vertices, faces)[0].sum())
    # a surface of area A meshed on a grid of cell c has about 2 A / c² triangles
    cell = np.sqrt(2.0 * area / max_faces)
    lower = vertices.min(axis=0)
    while True:
        keys = np.floor((vertices - lower) / cell).astype(np.int64)
        _, cluster, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
        cluster = cluster.ravel()
        merged = np.zeros((len(counts), 3))
        np.add.at(merged, cluster, vertices)
        merged /= counts[:, None]
        remapped = cluster[faces]
        whole = (
            (remapped[:, 0] != remapped[:, 1]) & (remapped[:, 1] != remapped[:, 2]) & (remapped[:, 0] != remapped[:, 2])
        )
        remapped = remapped[whole]
        _, first = np.unique(np.sort(remapped, axis=1), axis=0, return_index=True)
        remapped = remapped[np.sort(first)]
        if len(remapped) <= max_faces:
            return merged, remapped
        cell *= 1.25
