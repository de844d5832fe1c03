"""Mesh helpers shared by the method: clipping to boxes, manifold3d conversion, frames."""

from __future__ import annotations

import manifold3d
import numpy as np
import trimesh
from igl.embree import EmbreeIntersector
from scipy.spatial import ConvexHull

from .errors import GeometryError

#: Vertices this close to a clipping plane count as on it (mm): parts and
#: sample positions are built from round numbers and float32 files, so
#: faces meant to lie in a box face otherwise fall out by one rounding step.
PLANE_TOLERANCE_MM = 1e-7


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
        the box planes). ``faces`` is empty when nothing is inside. The
        input's vertices come first, unchanged, and cut points are appended
        (a soup: cut triangles do not share them), so indices into the input
        stay valid.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    lower, upper = np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64)
    # triangles wholly beyond one plane are dropped first, as that plane's pass would drop them: a small box on a
    # large part then cuts only the few triangles near it, instead of each pass sorting them all
    beyond = np.zeros(len(faces), dtype=bool)
    for axis in np.flatnonzero(np.isfinite(lower) | np.isfinite(upper)):
        lowest, highest = corner_extremes(vertices[:, axis][faces])
        beyond |= (highest - lower[axis] < -PLANE_TOLERANCE_MM) | (upper[axis] - lowest < -PLANE_TOLERANCE_MM)
    faces = faces[~beyond]
    for axis in range(3):
        for bound, sign in ((lower[axis], 1.0), (upper[axis], -1.0)):
            if len(faces) == 0:
                return vertices, faces[:0]
            if np.isfinite(bound):
                vertices, faces, _ = _clip_half_space(vertices, faces, axis, sign, bound * sign)
    return vertices, faces


def corner_extremes(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least and greatest of each triangle's three corners, elementwise.

    Parameters
    ----------
    corners : (m, 3) or (m, 3, k) array
        Axis 1 runs over the corners.

    Returns
    -------
    lowest, highest : (m,) or (m, k) array
        ``corners.min(axis=1)`` and ``corners.max(axis=1)``, exactly, taken
        as columns: numpy reduces along an axis of three several times slower.
    """
    first, second, third = corners[:, 0], corners[:, 1], corners[:, 2]
    return np.minimum(np.minimum(first, second), third), np.maximum(np.maximum(first, second), third)


def _half_space_sides(vertices: np.ndarray, faces: np.ndarray, axis: int, sign: float, level: float):
    """Which triangles lie wholly in ``sign * x[axis] >= level`` and which cross it (see :func:`_clip_half_space`).

    Returns
    -------
    distance : (m, 3) float
        Signed distance of each corner past the plane, mm.
    inside_count : (m,) int
        Corners on the kept side (within :data:`PLANE_TOLERANCE_MM`).
    whole, crossing : (m,) bool
        Triangles kept whole (an in-plane one by its normal) and triangles cut.
    """
    distance = vertices[:, axis][faces] * sign - level
    is_inside = distance >= -PLANE_TOLERANCE_MM
    is_on = np.abs(distance) <= PLANE_TOLERANCE_MM
    # corners as columns: numpy reduces along an axis of three slowly
    inside_count = is_inside[:, 0].astype(np.int64) + is_inside[:, 1] + is_inside[:, 2]
    whole = inside_count == 3
    on_plane = is_on[:, 0] & is_on[:, 1] & is_on[:, 2]
    if on_plane.any():
        corners = vertices[faces[on_plane]]
        normal_along_axis = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])[:, axis] * sign
        whole[on_plane] = normal_along_axis < 0.0
    return distance, inside_count, whole, (inside_count == 1) | (inside_count == 2)


def half_space_area(
    vertices: np.ndarray, faces: np.ndarray, face_areas: np.ndarray, axis: int, sign: float, level: float
) -> float:
    """Area of the surface where ``sign * x[axis] >= level``, mm²: the area :func:`clip_to_box` keeps, without cutting.

    Parameters
    ----------
    vertices, faces : ndarray
        The surface (mm).
    face_areas : (m,) float
        Area of each triangle, mm².
    axis : int
    sign : float
        +1 keeps ``x >= level``, -1 keeps ``x <= -level``.
    level : float

    A cut triangle keeps the fraction ``t1 * t2`` of its area when one
    corner is inside (``t`` the edge fractions from that corner to the
    plane), and ``1 - t1 * t2`` of the lone outside corner's when two are.
    """
    if len(faces) == 0:
        return 0.0
    distance, inside_count, whole, crossing = _half_space_sides(vertices, faces, axis, sign, level)
    cut_count = inside_count[crossing]
    rolled = np.take_along_axis(distance[crossing], _odd_corner_first(distance[crossing], cut_count), axis=1)
    corner_fraction = rolled[:, 0] / (rolled[:, 0] - rolled[:, 1]) * (rolled[:, 0] / (rolled[:, 0] - rolled[:, 2]))
    kept_fraction = np.where(cut_count == 1, corner_fraction, 1.0 - corner_fraction)
    return float(face_areas[whole].sum() + (face_areas[crossing] * kept_fraction).sum())


def _odd_corner_first(cut_distance: np.ndarray, cut_count: np.ndarray) -> np.ndarray:
    """Corner order of each cut triangle that puts its odd corner (the lone inside or lone outside one) first, (m,
    3).
    """
    cut_inside = cut_distance >= -PLANE_TOLERANCE_MM
    odd = np.where(cut_count == 1, np.argmax(cut_inside, axis=1), np.argmax(~cut_inside, axis=1))
    return (odd[:, None] + np.arange(3)) % 3


def _clip_half_space(
    vertices: np.ndarray, faces: np.ndarray, axis: int, sign: float, level: float | np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Keep the surface where ``sign * x[axis] >= level`` (within :data:`PLANE_TOLERANCE_MM`).

    Only triangles crossing the plane are cut (one vertex inside gives one
    triangle, two give two); the rest are kept or dropped whole, so most
    calls cost a comparison per triangle. A triangle lying in the plane is
    kept when its normal points out of the kept side, that is when the solid
    it bounds lies on the kept side (trimesh's rule), so a box's faces take
    the part's faces that lie on them exactly once. ``level`` may be an
    ``(m, 1)`` array, one plane per triangle.

    Returns the vertices (cut points appended), the kept triangles and, for
    each, the index of the input triangle it comes from.
    """
    distance, inside_count, whole, crossing = _half_space_sides(vertices, faces, axis, sign, level)
    kept = faces[whole]
    if not crossing.any():
        return vertices, kept, np.flatnonzero(whole)
    cut, cut_distance, cut_count = faces[crossing], distance[crossing], inside_count[crossing]
    order = _odd_corner_first(cut_distance, cut_count)
    rows = np.arange(len(cut))[:, None]
    cut, cut_distance = cut[rows, order], cut_distance[rows, order]
    first = vertices[cut[:, 0]]
    # points where the edges from the odd vertex cross the plane
    crossings = [
        first
        + (vertices[cut[:, k]] - first) * (cut_distance[:, 0] / (cut_distance[:, 0] - cut_distance[:, k]))[:, None]
        for k in (1, 2)
    ]
    count = len(cut)
    start = len(vertices)
    near_1, near_2 = start + np.arange(count), start + count + np.arange(count)
    lone_inside = cut_count == 1
    triangles = [
        np.column_stack([cut[lone_inside, 0], near_1[lone_inside], near_2[lone_inside]]),
        np.column_stack([near_1[~lone_inside], cut[~lone_inside, 1], cut[~lone_inside, 2]]),
        np.column_stack([near_1[~lone_inside], cut[~lone_inside, 2], near_2[~lone_inside]]),
    ]
    cut_sources = np.flatnonzero(crossing)
    sources = [np.flatnonzero(whole), cut_sources[lone_inside], cut_sources[~lone_inside], cut_sources[~lone_inside]]
    return np.vstack([vertices, *crossings]), np.vstack([kept, *triangles]), np.concatenate(sources)


def cut_at_levels(
    vertices: np.ndarray, faces: np.ndarray, axis: int, levels: np.ndarray
) -> tuple[np.ndarray, list[np.ndarray]]:
    """A surface cut at every level along an axis, as :func:`clip_to_box` would cut it between each two.

    Parameters
    ----------
    vertices : (n, 3) float
        mm.
    faces : (m, 3) int
    axis : int
    levels : (k,) float
        Ascending and distinct, mm.

    Returns
    -------
    vertices : ndarray
        The input's vertices first, unchanged, then the cut points.
    bands : list of k + 1 (j, 3) int arrays
        The triangles below ``levels[0]``, between each two levels, and
        above ``levels[-1]``.

    A triangle farther than the clipping tolerance from every level lies
    whole in one band. The others are cut in rounds, every one at the lowest
    level it still meets, so a round costs two cuts whatever the number of
    levels.
    """
    levels = np.asarray(levels, dtype=np.float64)
    # a triangle meets the levels from `lowest` up to (not including) `highest`
    margin = 2.0 * PLANE_TOLERANCE_MM

    def met_levels(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        low, high = corner_extremes(vertices[:, axis][triangles])
        return np.searchsorted(levels, low - margin, side="left"), np.searchsorted(levels, high + margin, side="right")

    lowest, highest = met_levels(faces)
    clear = lowest == highest
    placed, numbers = [faces[clear]], [lowest[clear]]
    pending, current = faces[~clear], lowest[~clear]
    while len(pending):
        level = levels[current][:, None]
        vertices, below, source = _clip_half_space(vertices, pending, axis, -1.0, -level)
        placed.append(below)
        numbers.append(current[source])
        vertices, above, source = _clip_half_space(vertices, pending, axis, 1.0, level)
        lowest, highest = met_levels(above)
        lowest = np.maximum(lowest, current[source] + 1)
        clear = lowest >= highest
        placed.append(above[clear])
        numbers.append(lowest[clear])
        pending, current = above[~clear], lowest[~clear]
    placed, numbers = np.vstack(placed), np.concatenate(numbers)
    order = np.argsort(numbers, kind="stable")
    return vertices, np.split(placed[order], np.cumsum(np.bincount(numbers, minlength=len(levels) + 1))[:-1])


def triangle_areas_normals(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Area (mm²) and unit normal of each triangle; zero-area triangles get a zero normal."""
    triangles = vertices[faces]
    first, second = triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]
    # written out: np.cross costs more than the arithmetic on arrays this small
    cross = np.column_stack(
        [
            first[:, 1] * second[:, 2] - first[:, 2] * second[:, 1],
            first[:, 2] * second[:, 0] - first[:, 0] * second[:, 2],
            first[:, 0] * second[:, 1] - first[:, 1] * second[:, 0],
        ]
    )
    doubled = np.sqrt(np.einsum("ij,ij->i", cross, cross))
    normals = np.zeros_like(cross)
    nonzero = doubled > 0
    normals[nonzero] = cross[nonzero] / doubled[nonzero, None]
    return doubled / 2.0, normals


def ray_hits(
    vertices: np.ndarray, faces: np.ndarray, origins: np.ndarray, directions: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Every crossing of rays with a triangle mesh, by Embree (through libigl).

    Parameters
    ----------
    vertices : (n, 3) float
        mm.
    faces : (m, 3) int
    origins : (r, 3) float
        mm.
    directions : (r, 3) float
        Unit vectors.

    Returns
    -------
    rays : (h,) int
        The ray of each hit, ascending.
    distances_mm : (h,) float
        From the ray's origin to the hit, ascending within a ray. Embree
        works in float32 (about 1e-6 of the distance) and reports a ray
        through a shared edge or vertex once.
    """
    intersector = EmbreeIntersector()
    intersector.init(np.asfortranarray(vertices, dtype=np.float32), np.asfortranarray(faces, dtype=np.int32), True)
    origins = np.ascontiguousarray(origins, dtype=np.float32)
    directions = np.ascontiguousarray(directions, dtype=np.float32)
    rays, distances = [], []
    for index in range(len(origins)):
        hits, _ = intersector.intersectRay(origins[index], directions[index])
        rays += [index] * len(hits)
        distances += [hit[1] for hit in hits]
    return np.asarray(rays, dtype=np.int64), np.asarray(distances, dtype=np.float64)


def volume_about(mesh: trimesh.Trimesh, origin: np.ndarray) -> float:
    """The divergence integral of ``mesh``'s triangles about ``origin`` (its signed volume if closed), units³.

    Unlike ``trimesh.Trimesh.volume`` it computes no centre of mass, so a piece of zero volume (a flap) raises no
    division warning.
    """
    corners = np.asarray(mesh.triangles, dtype=np.float64) - origin
    return float(np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])).sum() / 6.0)


def convex_patches(
    vertices: np.ndarray,
    corners: np.ndarray,
    normals: np.ndarray,
    tolerance_mm: float,
    min_cos: float = 1.0 - 1e-9,
    max_sag_mm: np.ndarray | None = None,
    seen_along: np.ndarray | None = None,
) -> list[list[int]]:
    """Triangles of a surface grouped into edge-connected clusters that form a convex patch.

    Greedy: a cluster grows from its first triangle by neighbours whose
    normal is within ``arccos(min_cos)`` of the first one's while (a) every
    corner of the cluster lies under the plane of every triangle of it (the
    patch is convex, within ``tolerance_mm``), and (b) the hull of
    its corners seen along the first normal (or ``seen_along``) has the area of its triangles
    (no notch or hole in its outline). Then the patch is the top of the hull
    of its corners and of their copies moved along the first normal, and the
    prism under it is convex. By default only coplanar triangles are grouped:
    a flat face or a planar wall of a pocket is one piece instead of one per
    triangle.

    Parameters
    ----------
    vertices : (n, 3) float
    corners : (m, 3) int
        The triangles' vertex indices.
    normals : (m, 3) float
        Unit normals of the triangles.
    tolerance_mm : float
        How far a corner of a patch may stand above the plane of one of its triangles, mm.
    min_cos : float
        Cosine of the largest angle between the normals of a cluster's triangles and its first one's.
    max_sag_mm : (m,) float, optional
        Largest depth of a cluster's corners along its first normal (the patch's bulge): a cluster's hull reaches
        that far under its patch. None: no limit.
    seen_along : (3,) float, optional
        Unit direction of the outline's test instead of each cluster's first normal (a pad's prisms run along its
        ``u`` axis).
    """
    area = np.linalg.norm(np.cross(*(vertices[corners[:, k]] - vertices[corners[:, 0]] for k in (1, 2))), axis=1) / 2
    offsets = np.einsum("ij,ij->i", normals, vertices[corners[:, 0]])
    neighbours: dict[tuple[int, int], list[int]] = {}
    for index, (a, b, c) in enumerate(corners):
        for edge in ((a, b), (b, c), (c, a)):
            neighbours.setdefault((min(edge), max(edge)), []).append(index)
    adjacent = [set() for _ in corners]
    for sharing in neighbours.values():
        for index in sharing:
            adjacent[index].update(t for t in sharing if t != index)
    taken = np.zeros(len(corners), dtype=bool)
    clusters = []
    for seed in range(len(corners)):
        if taken[seed]:
            continue
        taken[seed] = True
        normal = normals[seed]
        seen = normal if seen_along is None else np.asarray(seen_along, dtype=np.float64)
        cluster, shadow = [seed], float(area[seed] * abs(normal @ seen))
        frontier = [t for t in adjacent[seed] if normals[t] @ normal >= min_cos]
        if frontier:
            # two directions across the one seen along: the hull's area in them is the area seen along it
            across = np.cross(seen, np.eye(3)[np.argmin(np.abs(seen))])
            in_plane = np.column_stack([across, np.cross(seen, across)])
            in_plane /= np.linalg.norm(in_plane, axis=0)
        while frontier:
            candidate = frontier.pop()
            if taken[candidate]:
                continue
            members = cluster + [candidate]
            points = vertices[np.unique(corners[members])]
            grown = shadow + float(area[candidate] * abs(normals[candidate] @ seen))
            heights = points @ normal
            if (
                (normals[members] @ points.T - offsets[members, None]).max() <= tolerance_mm
                and (max_sag_mm is None or np.ptp(heights) <= max_sag_mm[members].min())
                and ConvexHull(points @ in_plane).volume <= grown * (1.0 + 1e-9) + 1e-9
            ):
                taken[candidate] = True
                cluster.append(candidate)
                shadow = grown
                frontier.extend(t for t in adjacent[candidate] if not taken[t] and normals[t] @ normal >= min_cos)
        clusters.append(cluster)
    return clusters


def mesh_arrays(solid: manifold3d.Manifold) -> tuple[np.ndarray, np.ndarray]:
    """``solid``'s vertices (mm, float64) and triangles: what a worker sends of a solid (manifold3d's do not pickle)."""
    mesh = solid.to_mesh64()
    return np.array(mesh.vert_properties), np.array(mesh.tri_verts)


def solid_from_mesh_arrays(vertices: np.ndarray, triangles: np.ndarray) -> manifold3d.Manifold:
    """The solid of :func:`mesh_arrays`."""
    return manifold3d.Manifold(manifold3d.Mesh64(vert_properties=vertices, tri_verts=triangles))


def rebuilt_from_mesh(solid: manifold3d.Manifold) -> manifold3d.Manifold:
    """``solid`` rebuilt from its own mesh, as a worker's result arrives.

    manifold3d's later Booleans triangulate a solid's history differently from
    its mesh, and a design must not depend on where its geometries were made.
    """
    return solid_from_mesh_arrays(*mesh_arrays(solid))


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
