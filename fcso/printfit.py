"""Fingers that fit after printing: clearance, lead-ins and thin walls of the pocket.

METHOD §4 carves the exact negative of the part. A printed part and a
printed finger both deviate from their meshes, so this module drafts the
pocket's walls by a lead-in angle ``α`` so that a displaced part is guided
in as the fingers close, gives it a clearance ``c`` and removes pad walls
thinner than the printer can make (a morphological opening).

The clearance becomes depth, not play (METHOD §9c): a drafted pocket is
the exact part moved ``c`` deeper into the pad, drafted. At its designed
depth the part is at least ``c sin α`` from every wall (``c`` from faces
that face the pad), and closing seats it ``c`` deeper on the drafted walls,
which centre it; a pocket printed smaller seats it shallower, still
centred. Grown by a ball of radius ``c`` instead (``G ⊕ ball(c)``, kept
where there is no lead-in), the part came to rest on the pocket's floor
with ``c (1 - sin α) / cos α`` of play at every wall parallel to the
closing axis (0.31 mm at 15°, beyond the 0.3 mm success tolerance).

Seating rule with a clearance (used by :func:`fcso.contact.seat`): as the
gripper closes, both pads travel toward the part until contact. A pad may
advance past the METHOD §6 seat by at most :func:`closing_travel_mm`
(``2 c``: enough to close a ball's clearance on every pocket wall within 60
degrees of facing the pad, and the ``c`` of a drafted pocket), so with
``c = 0`` seating is METHOD §6 exactly.

All Minkowski sums and differences are with convex kernels and exact
(:func:`minkowski_convex`, :func:`minkowski_difference_convex`): the solid
and the kernel swept over each convex planar patch of its surface, one
Boolean of all of them. manifold3d's own ``minkowski_sum`` sweeps every
triangle instead: a flat face of a CAD part, or a pad's, is many triangles
and as many overlapping sweeps, and the Boolean of them was the pockets'
and openings' cost (the 12-part job's sums 2.3x faster, its openings 1.6x).
Round kernels are polyhedra that contain the round shape, so grown pockets
are never smaller than asked.

The sweeps are hulls of the solid's own double-precision vertices plus the
kernel's, as manifold3d's are. An earlier union of hulls here (before
b31b3ef) built them from the solid's float32 mesh (``to_mesh``): their
faces then met the solid's and each other's only to float32 rounding
(1e-16..1e-7 mm), manifold3d's exact Booleans kept every such
near-coincidence as a sliver narrower than float32 resolution, and written
as a float32 STL the slivers collapsed into zero-area triangles and the
surface fell apart into pieces (a knurled knob's ``finger.stl``: 5 627
zero-area triangles, 1 688 pieces). That knob and every fixture part, with
every printer profile, are written and read back as one watertight body
by the tests of ``tests/fcso/test_written_meshes.py``.

The opening of :func:`open_thin_walls` dilates an erosion whose facets
carry slivers, and multiplies them (a 450-triangle pad opened into 53 000
triangles, 251 of zero area as written): its erosion and its result are
simplified to :data:`SIMPLIFY_TOLERANCE_MM`. What
float32 rounding itself makes degenerate is collapsed when a delivered
solid is written (:func:`fcso.finger.as_written`).
"""

from __future__ import annotations

from functools import lru_cache

import manifold3d
import numpy as np
import trimesh

from .geometry import (
    affine_3x4,
    box,
    convex_patches,
    mesh_arrays,
    ray_hits,
    rebuilt_from_mesh,
    to_trimesh,
    triangle_areas_normals,
)

#: Facets of the ball kernel: its vertices lie at most 8.5 % beyond the ball it contains.
BALL_SEGMENTS = 12
#: Facets of the lead-in cone's base circle (circumscribed: the draft is never under the angle).
CONE_SEGMENTS = 32
#: Features smaller than this are merged when a thin-wall opening is simplified, mm (a
#: thousandth of the finest printer's resolution, a hundred float32 steps at 100 mm).
SIMPLIFY_TOLERANCE_MM = 1e-4
#: How far from one plane the triangles of one swept patch of a Minkowski sum may lie, mm (a hundredth of
#: :data:`SIMPLIFY_TOLERANCE_MM`): a patch's hull contains its triangles, so a sum grows by at most this.
PATCH_TOLERANCE_MM = 1e-6


@lru_cache(maxsize=8)
def _unit_ball_points(segments: int) -> np.ndarray:
    """Vertices of manifold3d's sphere scaled so that its facets contain the unit ball."""
    mesh = manifold3d.Manifold.sphere(1.0, segments).to_mesh()
    vertices = np.asarray(mesh.vert_properties[:, :3], dtype=np.float64)
    triangles = vertices[np.asarray(mesh.tri_verts)]
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    inradius = float(np.abs(np.einsum("ij,ij->i", normals, triangles[:, 0])).min())
    return vertices / inradius


def ball_points(radius_mm: float, segments: int = BALL_SEGMENTS) -> np.ndarray:
    """Vertices of a convex polyhedron that contains the ball of ``radius_mm`` (centre at the origin).

    Returns
    -------
    (k, 3) float
        mm.
    """
    return _unit_ball_points(segments) * radius_mm


def cone_points(height_mm: float, angle_deg: float, segments: int = CONE_SEGMENTS) -> np.ndarray:
    """Vertices of the lead-in cone: apex at the origin, axis along ``-u``, half-angle ``angle_deg``.

    The base polygon at ``u = -height_mm`` circumscribes the circle of radius
    ``height_mm · tan(angle)``, so the draft is at least the angle in every
    direction and at most ``1 / cos(π / segments) - 1`` (0.5 %) wider.

    Returns
    -------
    (segments + 1, 3) float
        mm, pad frame (u, v, w).
    """
    radius = height_mm * np.tan(np.radians(angle_deg)) / np.cos(np.pi / segments)
    angles = 2.0 * np.pi * np.arange(segments) / segments
    base = np.column_stack([np.full(segments, -height_mm), radius * np.cos(angles), radius * np.sin(angles)])
    return np.vstack([np.zeros((1, 3)), base])


def minkowski_convex(solid: manifold3d.Manifold, kernel: np.ndarray) -> manifold3d.Manifold:
    """Minkowski sum of a solid with the convex hull of ``kernel`` points (exact).

    ``A ⊕ K = A ∪ ⋃_p hull(p ⊕ K)`` over the convex planar patches ``p`` of
    ``A``'s surface (:func:`fcso.geometry.convex_patches`); a convex ``A``
    is the hull of every vertex sum. A patch whose outward normal ``n`` has
    ``max_k n·k = 0`` (the kernel reaches no further than its origin that
    way: the lead-in cone's apex, for faces that face the pad's back) is
    left out: where ``A ⊕ K`` leaves ``A``, it is ``a + λK`` for a point
    ``a`` of ``A``'s surface where a plane with normal ``n`` supports ``A``
    and ``max_k n·k > 0``, so ``n`` is the normal of a patch kept through
    ``a`` (requires the kernel to hold the origin, as the ball and the cone
    do).

    Parameters
    ----------
    solid : manifold3d.Manifold
    kernel : (k, 3) float
        Points whose convex hull is the kernel and holds the origin (mm).

    Returns
    -------
    manifold3d.Manifold
    """
    if solid.is_empty():
        return solid
    kernel = np.asarray(kernel, dtype=np.float64)
    vertices, corners = mesh_arrays(solid)
    volume = solid.volume()
    if solid.hull().volume() - volume <= 1e-12 * max(volume, 1.0):
        return manifold3d.Manifold.hull_points((vertices[:, None, :3] + kernel[None]).reshape(-1, 3))
    return manifold3d.Manifold.batch_boolean(
        [solid, *_swept_patches(vertices, corners, kernel, reaching_only=True)], manifold3d.OpType.Add
    )


def minkowski_difference_convex(solid: manifold3d.Manifold, kernel: np.ndarray) -> manifold3d.Manifold:
    """Minkowski difference (erosion) of a solid by the convex hull of ``kernel`` points (exact).

    ``A ⊖ K = {x : x + K ⊆ A} = A - ⋃_p hull(p ⊕ -K)`` over the convex
    planar patches ``p`` of ``A``'s surface.

    Parameters
    ----------
    solid : manifold3d.Manifold
    kernel : (k, 3) float
        Points whose convex hull is the kernel (mm).

    Returns
    -------
    manifold3d.Manifold
    """
    if solid.is_empty():
        return solid
    vertices, corners = mesh_arrays(solid)
    swept = _swept_patches(vertices, corners, -np.asarray(kernel, dtype=np.float64), reaching_only=False)
    return manifold3d.Manifold.batch_boolean([solid, *swept], manifold3d.OpType.Subtract)


def _swept_patches(
    vertices: np.ndarray, corners: np.ndarray, kernel: np.ndarray, reaching_only: bool
) -> list[manifold3d.Manifold]:
    """``hull(p ⊕ K)`` for every convex planar patch ``p`` of a surface; with ``reaching_only``, only the patches
    whose normal ``n`` has ``max_k n·k > 0`` (see :func:`minkowski_convex`)."""
    vertices, corners = vertices[:, :3], corners.astype(np.int64)
    areas, normals = triangle_areas_normals(vertices, corners)
    # a zero-area triangle's sweep lies in its neighbours'
    corners, normals = corners[areas > 0.0], normals[areas > 0.0]
    swept = []
    for patch in convex_patches(vertices, corners, normals, PATCH_TOLERANCE_MM):
        if reaching_only and (normals[patch[0]] @ kernel.T).max() <= 0.0:
            continue
        points = vertices[np.unique(corners[patch])]
        swept.append(manifold3d.Manifold.hull_points((points[:, None, :] + kernel[None]).reshape(-1, 3)))
    return swept


def grow(part: manifold3d.Manifold, clearance_mm: float) -> manifold3d.Manifold:
    """The part grown by the clearance: ``G ⊕ ball(c)`` (the part itself when ``c = 0``).

    An offset surface, not a scale: every point of the grown surface is at
    least ``c`` from the part (the ball kernel contains the ball).
    """
    if clearance_mm <= 0:
        return part
    return minkowski_convex(part, ball_points(clearance_mm))


def draft(
    geometry: manifold3d.Manifold, pad_box: manifold3d.Manifold, height_mm: float, lead_in_deg: float
) -> manifold3d.Manifold:
    """The pocket geometry with its walls drafted by the lead-in: ``I ⊕ cone``, clipped to a box.

    Every point of ``I`` at depth ``u`` widens the pocket at every shallower
    ``u' < u`` by ``(u - u') tan(angle)``: the opening at the pad face
    (``u = 0``) is wider than the pocket at depth ``d`` by ``d tan(angle)``
    per side, faces of the part that face the pad (the deepest points) stay
    exact, and undercuts are filled toward the pad face, so the part can
    enter along the closing axis. A Minkowski sum with a cone keeps the angle
    for any pocket shape, where scaling an extrusion would not.

    Parameters
    ----------
    geometry : manifold3d.Manifold
        ``I_n`` (grown by the clearance), pad frame.
    pad_box : manifold3d.Manifold
        The box the result is clipped to (``S`` or larger).
    height_mm : float
        Deepest ``u`` of ``geometry`` (``D + c``): the cone's height.
    lead_in_deg : float
        0 returns ``geometry`` unchanged.
    """
    if lead_in_deg <= 0 or geometry.is_empty():
        return geometry
    return minkowski_convex(geometry, cone_points(height_mm, lead_in_deg)) ^ pad_box


def carve(
    part: manifold3d.Manifold,
    frame: np.ndarray,
    size_mm: tuple[float, float, float],
    depth_mm: float,
    clearance_mm: float,
    lead_in_deg: float,
) -> manifold3d.Manifold:
    """What one good pad geometry removes from the pad when printed fit is on.

    With a lead-in, the part moved ``c`` deeper along ``u``, drafted (METHOD
    §9c); without one, ``S ∩ (G_n ⊕ ball(c))``. Only the part within ``c``
    of the pad box can reach into it, so the part is clipped to the box
    grown by ``c`` before it is grown (the same set, far fewer triangles).

    Parameters
    ----------
    part : manifold3d.Manifold
        The part in its resting frame (mm).
    frame : (4, 4) float
        Resting frame to pad frame.
    size_mm : (T, L, W)
        The pad box.
    depth_mm : float
        Penetration D.
    clearance_mm, lead_in_deg : float
        0 and 0 give the exact ``I_n = S ∩ G_n`` of METHOD §4.

    Returns
    -------
    manifold3d.Manifold
        Pad frame; with clearance or lead-in it reaches up to 1 mm beyond
        ``S``, which only matters inside ``S``.
    """
    pad_box = box((0.0, 0.0, 0.0), size_mm)
    local = part.transform(affine_3x4(frame))
    if clearance_mm <= 0 and lead_in_deg <= 0:
        return local ^ pad_box
    if clearance_mm > 0 and lead_in_deg > 0:
        # the clearance becomes depth, not play (the module's note, METHOD §9c)
        local = local.translate([clearance_mm, 0.0, 0.0])
    elif clearance_mm > 0:
        margin = clearance_mm + 1e-3
        local = grow(local ^ box((-margin,) * 3, tuple(x + margin for x in size_mm)), clearance_mm)
    # clipped to a box 1 mm larger than S: no face of the carving lies on a face of S,
    # where subtracting it would leave zero-thickness pad sheets
    outer = box((-1.0,) * 3, tuple(x + 1.0 for x in size_mm))
    carved = local ^ outer
    if lead_in_deg > 0:
        # the cone's sum runs over every convex patch of the part's facets: merged within 1e-4 mm first, a
        # tessellated part has fewer of them, for a change of volume under 1e-4 mm³
        inside = (local ^ pad_box).as_original().simplify(SIMPLIFY_TOLERANCE_MM)
        carved = carved + draft(inside, outer, depth_mm + clearance_mm, lead_in_deg)
    return carved


def closing_travel_mm(clearance_mm: float) -> float:
    """How far past the METHOD §6 seat a pad may advance toward the part as the gripper closes.

    ``2 c`` closes the clearance on every wall whose normal is within 60
    degrees of the closing axis (``c / cos 60°``); 0 without clearance, so
    seating is METHOD §6 exactly.
    """
    return 2.0 * clearance_mm


def _backed(
    pad: manifold3d.Manifold, thickness_mm: float, length_mm: float, width_mm: float, backing_mm: float
) -> manifold3d.Manifold:
    """The pad with a slab behind its back face (``u`` in ``[T, T + backing]``).

    Material fused to the finger is never a thin wall.
    """
    return pad + box((thickness_mm - 1e-3, 0.0, 0.0), (thickness_mm + backing_mm, length_mm, width_mm))


def open_thin_walls(
    pad: manifold3d.Manifold, thickness_mm: float, length_mm: float, width_mm: float, min_wall_mm: float
) -> manifold3d.Manifold:
    """Remove pad walls and slivers thinner than ``min_wall_mm``: a morphological opening.

    ``P ∘ B = (P ⊖ B) ⊕ B`` with ``B`` a ball of diameter ``min_wall_mm``:
    what no such ball inside the pad can reach goes. The erosion and the
    result are simplified to :data:`SIMPLIFY_TOLERANCE_MM` (see the module's
    note on slivers). The pad is opened with a slab behind its back face
    (it is fused to the finger there), then clipped back to the pad box. An
    opening never adds material (beyond that tolerance), so a clearance stays a clearance. Convex
    edges of the pad are rounded to radius ``min_wall_mm / 2``; a pad whose
    thinnest wall (:func:`thinnest_wall_mm`) already meets the minimum is
    returned unchanged. The opening is a function of the pad's mesh: the
    same mesh opens the same, however the pad was built.

    Parameters
    ----------
    pad : manifold3d.Manifold
        ``P``, pad frame (mm).
    thickness_mm, length_mm, width_mm : float
        T, L and W of the pad box.
    min_wall_mm : float
        0 returns ``pad`` unchanged.

    Returns
    -------
    manifold3d.Manifold
        The opened pad, only its pieces attached to the back face.
    """
    if min_wall_mm <= 0:
        return pad
    # no wall under the minimum: the opening would only round convex edges, so skip it
    if thinnest_wall_mm(pad, thickness_mm, length_mm, width_mm) >= min_wall_mm:
        return pad
    # manifold3d's Booleans triangulate by their operands' history as well as their meshes
    pad = rebuilt_from_mesh(pad)
    kernel = ball_points(min_wall_mm / 2.0)
    # the pad's facets carry the carvings' slivers too, and the erosion sums the kernel over every one of them
    # (13 s for a 960-triangle pad of the 12-part job, 7 s simplified: 476 triangles)
    backed = _backed(pad, thickness_mm, length_mm, width_mm, 2.0 * min_wall_mm).as_original()
    backed = backed.simplify(SIMPLIFY_TOLERANCE_MM)
    # the erosion's facets carry slivers far below any printer's resolution, and the
    # dilation sums the kernel over every one of them: merge them first
    eroded = minkowski_difference_convex(backed, kernel).as_original().simplify(SIMPLIFY_TOLERANCE_MM)
    # so does the dilation's (sliver faces where the kernel's copies meet)
    opened = (
        (minkowski_convex(eroded, kernel) ^ box((0.0, 0.0, 0.0), (thickness_mm, length_mm, width_mm)))
        .as_original()
        .simplify(SIMPLIFY_TOLERANCE_MM)
    )
    pieces = [p for p in opened.decompose() if p.bounding_box()[3] >= thickness_mm - 1e-4]
    return (
        manifold3d.Manifold.batch_boolean(pieces, manifold3d.OpType.Add)
        if len(pieces) > 1
        else (pieces[0] if pieces else opened)
    )


def thinnest_wall_mm(
    pad: manifold3d.Manifold,
    thickness_mm: float,
    length_mm: float,
    width_mm: float,
    density_per_mm2: float = 2.0,
    seed: int = 0,
) -> float:
    """The pad's thinnest wall: the shortest run of material behind its surface, mm.

    Points spread by area over the pad's surface in front of its back face
    (``u < T``); from each, a ray goes into the material along the inward
    normal, and the wall there is the distance to where it leaves. The pad
    is measured with a slab behind its back face, as it is fused to the
    finger, so the section to the back face is not a wall.

    Returns
    -------
    float
        mm; ``inf`` for an empty pad.
    """
    backing = 2.0 * thickness_mm
    mesh = to_trimesh(_backed(pad, thickness_mm, length_mm, width_mm, backing))
    if len(mesh.faces) == 0:
        return float("inf")
    count = max(int(np.ceil(mesh.area * density_per_mm2)), 1)
    points, faces = trimesh.sample.sample_surface(mesh, count, seed=seed)
    front = points[:, 0] < thickness_mm - 1e-6
    points, normals = points[front], mesh.face_normals[faces[front]]
    if len(points) == 0:
        return float("inf")
    # start just outside the surface: the first hit is the entry, the second the exit
    lift = 1e-3
    rays, distances = ray_hits(mesh.vertices, mesh.faces, points + lift * normals, -normals)
    # a ray grazing a shared edge may still meet both of its triangles
    distinct = np.r_[True, (rays[1:] != rays[:-1]) | (np.diff(distances) > 1e-5)]
    rays, distances = rays[distinct], distances[distinct]
    first = np.r_[True, rays[1:] != rays[:-1]]
    second = np.r_[False, first[:-1]] & ~first
    if not second.any():
        return float("inf")
    return float((distances[second] - distances[np.flatnonzero(second) - 1]).min())
