"""Mesh helpers shared by the method: clipping to boxes, manifold3d conversion, frames."""

from __future__ import annotations

import manifold3d
import numpy as np
import trimesh

from .errors import GeometryError


def clip_to_box(vertices: np.ndarray, faces: np.ndarray, lower, upper) -> tuple[np.ndarray, np.ndarray]:
    """Clip a triangle soup to an axis-aligned box.

    Parameters
    ----------
    vertices : (n, 3) float
        Vertex coordinates.
    faces : (m, 3) int
        Triangles.
    lower, upper : sequence of 3 floats
        Box corners; ``-inf``/``inf`` leave that side open.

    Returns
    -------
    vertices, faces : ndarray
        The part of the surface inside the box (triangles cut exactly at
        the box planes). ``faces`` is empty when nothing is inside.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    for axis in range(3):
        for bound, sign in ((lower[axis], 1.0), (upper[axis], -1.0)):
            if len(faces) == 0:
                return vertices[:0], faces[:0]
            if not np.isfinite(bound):
                continue
            coordinate = vertices[faces, axis] * sign
            level = bound * sign
            inside = coordinate.min(axis=1) >= level
            straddling = ~inside & (coordinate.max(axis=1) >= level)
            if not straddling.any():
                faces = faces[inside]
                continue
            # only triangles crossing the plane are cut; the rest are kept or dropped whole
            cut = faces[straddling]
            used, remapped = np.unique(cut, return_inverse=True)
            normal = np.zeros(3)
            normal[axis] = sign
            origin = np.zeros(3)
            origin[axis] = bound
            cut_vertices, cut_faces = trimesh.intersections.slice_faces_plane(vertices[used], remapped.reshape(-1, 3), normal, origin)[:2]
            faces = np.vstack([faces[inside], np.asarray(cut_faces, dtype=np.int64) + len(vertices)])
            vertices = np.vstack([vertices, cut_vertices])
    return vertices, faces


def triangle_areas_normals(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Area (mm²) and unit normal of each triangle; zero-area triangles get a zero normal."""
    triangles = vertices[faces]
    cross = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    doubled = np.linalg.norm(cross, axis=1)
    normals = np.zeros_like(cross)
    nonzero = doubled > 0
    normals[nonzero] = cross[nonzero] / doubled[nonzero, None]
    return doubled / 2.0, normals


def to_manifold(mesh: trimesh.Trimesh) -> manifold3d.Manifold:
    """Convert a watertight trimesh to a :class:`manifold3d.Manifold`.

    Raises
    ------
    GeometryError
        When manifold3d does not accept the mesh as a manifold.
    """
    manifold = manifold3d.Manifold(
        manifold3d.Mesh(
            vert_properties=np.ascontiguousarray(mesh.vertices, dtype=np.float32),
            tri_verts=np.ascontiguousarray(mesh.faces, dtype=np.uint32),
        )
    )
    if manifold.status() != manifold3d.Error.NoError:
        raise GeometryError(f"manifold3d refused the mesh: {manifold.status()}")
    return manifold


def to_trimesh(manifold: manifold3d.Manifold) -> trimesh.Trimesh:
    """Convert a :class:`manifold3d.Manifold` to a trimesh (float64 vertices)."""
    mesh = manifold.to_mesh()
    return trimesh.Trimesh(
        vertices=np.asarray(mesh.vert_properties[:, :3], dtype=np.float64),
        faces=np.asarray(mesh.tri_verts, dtype=np.int64),
        process=False,
    )


def box(lower, upper) -> manifold3d.Manifold:
    """Axis-aligned box manifold spanning ``lower`` to ``upper`` (mm)."""
    lower = np.asarray(lower, dtype=float)
    size = np.asarray(upper, dtype=float) - lower
    return manifold3d.Manifold.cube(size.tolist()).translate(lower.tolist())


def affine_3x4(matrix: np.ndarray) -> list[list[float]]:
    """The top three rows of a 4x4 homogeneous matrix, as manifold3d wants them."""
    return np.asarray(matrix, dtype=float)[:3, :4].tolist()


def transform_points(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a 4x4 homogeneous transform to (n, 3) points."""
    return points @ matrix[:3, :3].T + matrix[:3, 3]
