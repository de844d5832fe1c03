"""Collision geometry that keeps concavities, and its fidelity (METHOD §12).

MuJoCo collides a mesh by its convex hull, so

- the carved fingerpad is cut into prisms under its face
  (:func:`pad_prism_pieces`): the pad is ``{u >= H(v, w)}`` over its
  ``(v, w)`` face, carved along ``u``, with ``H`` piecewise linear, so the
  prism between each facet of its face and its back face is convex and the
  prisms are the pad exactly (coplanar facets share a prism while their
  shadow stays convex). No decomposition is searched: the bunny's pad takes
  a few seconds instead of minutes of CoACD, and the seated overlap that
  CoACD's pad pieces made (they bridged pockets by up to 1 mm) is gone;
- the part is cut the same way where a pad can touch it
  (:func:`part_shell_pieces`): every facet of its surface there is the top
  of a prism 1 mm deep along the facet's inward normal (neighbouring
  facets share one while they form a convex patch), exact to the surface,
  hollow under it; elsewhere its material by cells is its hull. CoACD
  decomposed it before: its pieces bridged the part's concavities (the
  bunny's seated pad overlapped them by 0.21 mm in pose 1) and took
  minutes on organic parts (the bunny 2262 s cold); the shell takes
  seconds;
- pieces are cached by content hash on disk (shared by candidates, jobs,
  restarts and concurrent workers; written under a name of its own and
  renamed, :mod:`fcso.sim.diskcache`; the verification keeps the folder
  within its size once at its end); the fidelity is the volume of the
  union of the pieces against the mesh's own (:func:`volume_errors`),
  measured only for a verification told in full and cached beside them:
  its Boolean union is the costliest step of the pieces, and nobody reads
  it for a candidate the choice by truth rejects;
- the finger body behind the pad is the convex hull of the finger's
  material behind the pad's back face.

A height field of the pad's face (MuJoCo's ``hfield``) was tried first for the pad:
MuJoCo collides it prism by prism of its grid, 10x slower than the pieces
and with hundreds of contacts per step. Boxes over a ``(v, w)`` grid of
column heights, merged where their heights lie on one plane, were tried
for this module: a staircase off the pad by half a cell at every ridge
(the paper cube's median error 0.09 mm against 0.02 mm with the
prisms) and 1000-5000 pieces for the bunny's pad (0.2-0.05 mm cells).
Merging prisms across a convex crease too (a ridge as one piece, the
bunny's pad in 261 pieces instead of 346) made MuJoCo's contacts less
exact: the sanity tests' fingers closed 0.27 mm past their seat.
MuJoCo's signed distance fields of meshes (``needsdf``, a ``type="sdf"``
geom; no decomposition at all) made 2-7 contacts where the prisms make
39-289, and the bunny slipped out of its pads in every pose; with 200
start points 10-20x slower and still dropped (``CHANGELOG.md``, issue 22).
"""

from __future__ import annotations

import hashlib
import io
import zipfile
from dataclasses import dataclass
from pathlib import Path

import manifold3d
import numpy as np
import trimesh

from ..geometry import box, convex_patches, ray_hits, to_manifold
from .diskcache import read_entry, write_entry

#: Bumped when the decomposition's inputs or method change, so old cache entries are not reused.
CACHE_VERSION = "shell-6"
#: Largest deviation of the simplified surfaces the prisms are built on, mm (a pad carved with a print clearance has
#: ~35k triangles of offset surface).
SIMPLIFY_TOLERANCE_MM = 0.005
#: How far a corner of a convex patch of the part's or pad's surface may stand above the plane of one of its triangles,
#: mm (see :func:`fcso.geometry.convex_patches`).
CONVEX_TOLERANCE_MM = 0.001
#: Largest angle between the normals of the facets of one of the part's prisms, degrees (see :func:`part_shell_pieces`).
PATCH_BEND_DEG = 30.0


@dataclass
class ConvexPieces:
    """A mesh as convex pieces.

    Attributes
    ----------
    pieces : list of (vertices (n, 3) float, faces (m, 3) int)
        Convex meshes in the mesh's frame, mm.
    mesh : trimesh.Trimesh
        The mesh they were cut from (for :func:`volume_errors`).
    key : str
        Content hash of the mesh and the decomposition's settings (:func:`mesh_key`); empty: not cached.
    cached : bool
        Whether the pieces came from the cache.
    """

    pieces: list[tuple[np.ndarray, np.ndarray]]
    mesh: trimesh.Trimesh
    key: str
    cached: bool


def mesh_key(vertices: np.ndarray, faces: np.ndarray, settings: str) -> str:
    """Content hash of a mesh's geometry and the decomposition settings (hex sha256).

    ``settings`` is any text that names the decomposition (its thresholds,
    zones); it is hashed with the triangles.

    The hash is of the triangles themselves, at float32 precision (an STL's),
    each turned to start at its smallest corner and all sorted: the same
    surface read from a file or built in memory, with its vertices numbered
    differently, has the same key.
    """
    triangles = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)].astype("<f4")
    # start each triangle at its lexicographically smallest corner, keeping its orientation
    keys = triangles.view([("x", "<f4"), ("y", "<f4"), ("z", "<f4")]).reshape(len(triangles), 3)
    first = np.argmin(np.argsort(np.argsort(keys, axis=1, order=("x", "y", "z")), axis=1), axis=1)
    turned = triangles[np.arange(len(triangles))[:, None], (first[:, None] + np.arange(3)) % 3]
    flat = turned.reshape(len(turned), 9)
    ordered = flat[np.lexsort(flat.T[::-1])]
    digest = hashlib.sha256(CACHE_VERSION.encode())
    digest.update(np.ascontiguousarray(ordered).tobytes())
    digest.update(settings.encode())
    return digest.hexdigest()


def part_shell_pieces(
    mesh: trimesh.Trimesh,
    to_zones: np.ndarray,
    reach_boxes: np.ndarray,
    shell_mm: float,
    cache_dir: Path | None,
) -> ConvexPieces:
    """Convex pieces of a part from its own surface where the pads can reach it, its hull by cells elsewhere, cached
    by content hash.

    Where a pad can touch the part (any of ``reach_boxes``), every facet of
    the part's surface is the top of a prism that reaches ``shell_mm`` into
    the part along the facet's inward normal (less where the part is
    thinner: half its thickness under the facet, so no prism pokes out of a
    thin wall); neighbouring facets share a prism while they form a convex
    patch (normals within :data:`PATCH_BEND_DEG`, a bulge no deeper than
    the prism; :func:`fcso.geometry.convex_patches`). The prisms' outer faces are the surface itself:
    they stand out of the part by nothing, so nothing bridges a concavity,
    and no decomposition is searched. The material under the shell is left
    out (a pad that pushes its contact deeper than half the shell's
    thickness would be pushed out the wrong side; see ``part_shell_mm``).
    Elsewhere the planes of the boxes' faces cut space into a grid of
    cells and the part's material in each cell outside every box is its
    convex hull: it never reaches into a box, where the pads act, and only
    the finger bodies could meet it (the table meets the part's own hull,
    :func:`fcso.sim.scene.build_scene`).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Closed part mesh, mm.
    to_zones : (4, 4) float
        The mesh's frame to the boxes' frame.
    reach_boxes : (k, 2, 3) float
        Lower and upper corners of the boxes (boxes' frame, mm).
    shell_mm : float
        Depth of the prisms under the surface, mm.
    cache_dir : Path or None
        Folder of cached pieces; None: no cache.

    Returns
    -------
    ConvexPieces
        Pieces in the mesh's frame; its missing fraction is the material under the shell.
    """
    to_zones = np.asarray(to_zones, dtype=np.float64)
    reach_boxes = np.asarray(reach_boxes, dtype=np.float64).reshape(-1, 2, 3)
    settings = f"shell {float(shell_mm)!r} {np.round(to_zones, 6).tolist()} {np.round(reach_boxes, 4).tolist()}"
    return _cached_pieces(mesh, settings, lambda: _shell(mesh, to_zones, reach_boxes, shell_mm), cache_dir)


def _shell(mesh, to_zones, reach_boxes, shell_mm) -> list[tuple[np.ndarray, np.ndarray]]:
    moved = mesh.copy()
    moved.apply_transform(to_zones)
    part = to_manifold(moved).simplify(SIMPLIFY_TOLERANCE_MM)
    back = np.linalg.inv(to_zones)
    return [
        (vertices @ back[:3, :3].T + back[:3, 3], faces)
        for vertices, faces in _surface_prisms(part, reach_boxes, shell_mm) + _outer_hulls(part, reach_boxes)
    ]


def _surface_prisms(part: manifold3d.Manifold, reach_boxes: np.ndarray, shell_mm: float):
    """The prisms under the part's facets that meet a box (see :func:`part_shell_pieces`)."""
    surface = part.to_mesh64()
    vertices = np.asarray(surface.vert_properties[:, :3], dtype=np.float64)
    corners = all_corners = np.asarray(surface.tri_verts, dtype=np.int64)
    triangles = vertices[corners]
    low, high = triangles.min(axis=1), triangles.max(axis=1)
    reached = np.any(
        np.all((low[:, None] <= reach_boxes[None, :, 1]) & (high[:, None] >= reach_boxes[None, :, 0]), axis=2), axis=1
    )
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    lengths = np.linalg.norm(normals, axis=1)
    keep = reached & (lengths > 1e-12)
    corners, normals = corners[keep], normals[keep] / lengths[keep, None]
    depth = np.minimum(shell_mm, _thickness_under_mm(vertices, all_corners, vertices[corners], normals) / 2.0)
    pieces = []
    for cluster in convex_patches(
        vertices, corners, normals, CONVEX_TOLERANCE_MM, np.cos(np.radians(PATCH_BEND_DEG)), depth
    ):
        top = vertices[np.unique(corners[cluster])]
        prism = manifold3d.Manifold.hull_points(np.vstack([top, top - normals[cluster[0]] * depth[cluster].min()]))
        mesh = prism.to_mesh64()
        if prism.volume() > 1e-9:
            pieces.append(
                (np.asarray(mesh.vert_properties[:, :3], dtype=np.float64), np.asarray(mesh.tri_verts, dtype=np.int64))
            )
    return pieces


def _thickness_under_mm(vertices: np.ndarray, faces: np.ndarray, triangles: np.ndarray, normals: np.ndarray):
    """The part's thickness under each facet: the shortest distance to its other side along the inward normal from
    the facet's centre and from points near its corners, mm (inf where no ray leaves the part).

    Parameters
    ----------
    vertices, faces : ndarray
        The part's surface.
    triangles : (m, 3, 3) float
        The facets.
    normals : (m, 3) float
        Their outward unit normals.
    """
    centres = triangles.mean(axis=1)
    starts = np.concatenate([centres[:, None], 0.8 * triangles + 0.2 * centres[:, None]], axis=1).reshape(-1, 3)
    inward = np.repeat(-normals, 4, axis=0)
    # start just inside the facet so the ray does not hit the facet itself
    rays, distances = ray_hits(vertices, faces, starts + inward * 1e-3, inward)
    thickness = np.full(len(starts), np.inf)
    np.minimum.at(thickness, rays, distances + 1e-3)
    return thickness.reshape(-1, 4).min(axis=1)


def _outer_hulls(part: manifold3d.Manifold, reach_boxes: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The hull of the part's material in each cell of the grid the boxes' faces cut, outside every box."""
    lower, upper = np.asarray(part.bounding_box()[:3]) - 1.0, np.asarray(part.bounding_box()[3:]) + 1.0
    planes = [
        np.unique(
            np.clip(
                np.concatenate([[lower[axis], upper[axis]], reach_boxes[:, :, axis].ravel()]), lower[axis], upper[axis]
            )
        )
        for axis in range(3)
    ]
    pieces = []
    for i, j, k in np.ndindex(*(len(p) - 1 for p in planes)):
        cell_lower = np.array([planes[0][i], planes[1][j], planes[2][k]])
        cell_upper = np.array([planes[0][i + 1], planes[1][j + 1], planes[2][k + 1]])
        centre = (cell_lower + cell_upper) / 2.0
        if np.any(np.all((reach_boxes[:, 0] <= centre) & (centre <= reach_boxes[:, 1]), axis=1)):
            continue
        for component in (part ^ box(cell_lower, cell_upper)).decompose():
            if component.volume() < 1e-6:
                continue
            hull = component.hull().to_mesh64()
            pieces.append(
                (np.asarray(hull.vert_properties[:, :3], dtype=np.float64), np.asarray(hull.tri_verts, dtype=np.int64))
            )
    return pieces


#: Pad prisms thinner than this are left out, mm (a thousandth of the finest printer's resolution).
MIN_PIECE_WIDTH_MM = 1e-3
#: Pad prisms smaller than this are left out, mm³: MuJoCo refuses a mesh under 1e-15 m³ (1e-6 mm³), and a needle
#: under a sliver of the face can be wider than MIN_PIECE_WIDTH_MM and still that small (a slotted block's pad:
#: 9.6e-7 mm³); its neighbours hold that material.
MIN_PIECE_VOLUME_MM3 = 1e-5


def pad_prism_pieces(pad: trimesh.Trimesh, thickness_mm: float, cache_dir: Path | None) -> ConvexPieces:
    """Convex pieces of a carved pad from its own face, cached by content hash.

    The pad is ``P = {u >= H(v, w)}`` in its box ``[0, T] x [0, L] x [0, W]``
    (METHOD §8b's columns; the part is carved along ``u``): ``H`` is
    piecewise linear, one plane per triangle of the pad's face (the
    triangles a ray along ``+u`` enters the material through). Under each
    such triangle the pad is the prism between the triangle and the back
    face ``u = T``, which is convex: the prisms are the pad exactly, and no
    decomposition is searched (under a second for the bunny's pad). Pad
    material the part overhangs (a stretch of the part between it and the
    front, along ``u``) is left out, as the design's column heights leave
    it out: the pocket's faces that face ``-u`` are first swept towards
    ``-u`` and taken away from the pad. The volume
    error says how much that is (the bunny's pad: 4.8 %). The mesh
    is first simplified within :data:`SIMPLIFY_TOLERANCE_MM` (a pad carved
    with a print clearance has ~35k triangles of offset surface).

    Parameters
    ----------
    pad : trimesh.Trimesh
        The carved pad, pad frame, mm.
    thickness_mm : float
        Pad thickness T: the back face is ``u = T``.
    cache_dir : Path or None
        Folder of cached pieces; None: no cache.

    Returns
    -------
    ConvexPieces
        Pieces in the pad frame.
    """
    # the least volume is in the key: decompositions cached with smaller pieces than MuJoCo accepts are not reused
    settings = f"prisms {float(thickness_mm)!r} least {MIN_PIECE_VOLUME_MM3!r} mm3"
    return _cached_pieces(pad, settings, lambda: _prisms(pad, thickness_mm), cache_dir)


def _prisms(pad: trimesh.Trimesh, thickness_mm: float) -> list[tuple[np.ndarray, np.ndarray]]:
    solid = to_manifold(pad).simplify(SIMPLIFY_TOLERANCE_MM)
    lower, upper = np.asarray(solid.bounding_box()[:3]), np.asarray(solid.bounding_box()[3:])
    front, back = min(0.0, float(lower[0])) - 1.0, max(float(thickness_mm), float(upper[0]))
    region = box((front, lower[1], lower[2]), (back, upper[1], upper[2]))
    # what the columns leave out: the pad's material with carved pocket in front of it along +u (an overhang). A ray
    # from such a point along +u enters the pocket through one of the pocket's triangles that face -u, so it is the
    # union of those triangles' sweeps towards -u (a fraction of the pocket's triangles: the sweeps were the costliest
    # part of this function)
    pocket = (region - solid).to_mesh64()
    triangles = np.asarray(pocket.vert_properties[:, :3], dtype=np.float64)[np.asarray(pocket.tri_verts)]
    facing = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])[:, 0]
    # the region's own front face faces -u too, with nothing of the pad in front of it
    triangles = triangles[(facing < 0.0) & (triangles[:, :, 0].max(axis=1) > front)]
    sweeps = []
    for triangle in triangles:
        swept = manifold3d.Manifold.hull_points(np.vstack([triangle, triangle - [back - front, 0.0, 0.0]]))
        if swept.volume() > 1e-12:
            sweeps.append(swept)
    columns = solid - manifold3d.Manifold.batch_boolean(sweeps, manifold3d.OpType.Add) if sweeps else solid
    face = columns.simplify(SIMPLIFY_TOLERANCE_MM).to_mesh64()
    vertices = np.asarray(face.vert_properties[:, :3], dtype=np.float64)
    corners = np.asarray(face.tri_verts, dtype=np.int64)
    normals = np.cross(
        vertices[corners[:, 1]] - vertices[corners[:, 0]], vertices[corners[:, 2]] - vertices[corners[:, 0]]
    )
    # material is entered along +u through the triangles facing -u (twice their shadow's area, mm^2); walls have none
    corners, normals = corners[-normals[:, 0] > 2e-6], normals[-normals[:, 0] > 2e-6]
    pieces = []
    for cluster in convex_patches(
        vertices,
        corners,
        normals / np.linalg.norm(normals, axis=1, keepdims=True),
        CONVEX_TOLERANCE_MM,
        seen_along=np.array([1.0, 0.0, 0.0]),
    ):
        top = vertices[np.unique(corners[cluster])]
        behind = top.copy()
        behind[:, 0] = back
        solid_prism = manifold3d.Manifold.hull_points(np.vstack([top, behind]))
        if solid_prism.volume() < MIN_PIECE_VOLUME_MM3:
            continue
        prism = solid_prism.to_mesh64()
        piece = (
            np.asarray(prism.vert_properties[:, :3], dtype=np.float64),
            np.asarray(prism.tri_verts, dtype=np.int64),
        )
        # under a sliver triangle of the face (a knurled knob's pad: 17 nm wide) the prism is flat, and MuJoCo
        # refuses a flat mesh; its neighbours hold that material
        if len(piece[1]) and hull_width_mm(*piece) >= MIN_PIECE_WIDTH_MM:
            pieces.append(piece)
    return pieces


def hull_width_mm(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Width of a convex piece: its least extent across any of its faces' planes, mm."""
    normals = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    lengths = np.linalg.norm(normals, axis=1)
    normals = normals[lengths > 0] / lengths[lengths > 0, None]
    if len(normals) == 0:
        return 0.0
    return float(np.ptp(vertices @ normals.T, axis=0).min())


def _cached_pieces(mesh: trimesh.Trimesh, settings: str, decompose, cache_dir: Path | None) -> ConvexPieces:
    """Pieces from the cache (key: the mesh and ``settings``) or from ``decompose()``."""
    key = mesh_key(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64), settings)
    path = None if cache_dir is None else Path(cache_dir) / f"{key}.npz"
    stored = None if path is None else _read_cached(path)
    if stored is not None:
        return ConvexPieces(pieces=stored, mesh=mesh, key=key, cached=True)
    pieces = decompose()
    if path is not None:
        write_entry(path, _write_pieces(pieces))
    return ConvexPieces(pieces=pieces, mesh=mesh, key=key, cached=False)


def volume_errors(pieces: ConvexPieces, cache_dir: Path | None) -> tuple[float, float]:
    """Excess and missing volume of ``pieces`` against their mesh (:func:`union_volume_errors`), cached beside them.

    Measured on demand: the Boolean union of every piece takes longer than
    cutting them (a fifth of a second for a part's 80 pieces, a second for
    the xyz cube's 290 pad prisms), and only a verification told in full
    reports it.

    Returns
    -------
    excess, missing : float
        Volume of (union - mesh) and of (mesh - union), each over the mesh's volume.
    """
    path = None if cache_dir is None or not pieces.key else Path(cache_dir) / f"{pieces.key}-volume.npz"
    data = None if path is None else read_entry(path)
    try:
        if data is not None:
            with np.load(io.BytesIO(data)) as stored:
                excess, missing = (float(x) for x in stored["volume_errors"])
                return excess, missing
    except (OSError, ValueError, KeyError, zipfile.BadZipFile):
        pass  # a damaged entry is measured again
    errors = union_volume_errors(pieces.mesh, pieces.pieces)
    if path is not None:
        buffer = io.BytesIO()
        np.savez(buffer, volume_errors=np.asarray(errors, dtype=np.float64))
        write_entry(path, buffer.getvalue())
    return errors


def _read_cached(path: Path) -> list[tuple[np.ndarray, np.ndarray]] | None:
    """A cache entry's pieces, or None when it is absent or unreadable (then it is made again)."""
    data = read_entry(path)
    try:
        return None if data is None else _read_pieces(data)
    except (OSError, ValueError, KeyError, zipfile.BadZipFile):
        return None


def _write_pieces(pieces) -> bytes:
    """A cache entry: every piece's vertices and faces stacked, with the counts that split them again (a few arrays
    instead of two per piece: the xyz cube's 290 pad prisms write and read in milliseconds, not a third of a second).
    """
    buffer = io.BytesIO()
    vertices = [np.asarray(v, dtype=np.float64).reshape(-1, 3) for v, _ in pieces]
    faces = [np.asarray(f, dtype=np.int64).reshape(-1, 3) for _, f in pieces]
    np.savez_compressed(
        buffer,
        vertices=np.concatenate(vertices) if pieces else np.zeros((0, 3)),
        faces=np.concatenate(faces) if pieces else np.zeros((0, 3), dtype=np.int64),
        vertex_counts=np.array([len(v) for v in vertices], dtype=np.int64),
        face_counts=np.array([len(f) for f in faces], dtype=np.int64),
    )
    return buffer.getvalue()


def _read_pieces(data: bytes) -> list[tuple[np.ndarray, np.ndarray]]:
    with np.load(io.BytesIO(data)) as stored:
        vertex_counts, face_counts = stored["vertex_counts"], stored["face_counts"]
        if len(vertex_counts) == 0:
            return []
        vertices = np.split(stored["vertices"], np.cumsum(vertex_counts)[:-1])
        faces = np.split(stored["faces"], np.cumsum(face_counts)[:-1])
        return list(zip(vertices, faces))


def union_volume_errors(mesh: trimesh.Trimesh, pieces) -> tuple[float, float]:
    """Excess and missing volume of a set of convex pieces against the part.

    Returns
    -------
    excess, missing : float
        Volume of (union - part) and of (part - union), each over the part's volume.
    """
    part = to_manifold(mesh)
    union = manifold3d.Manifold.batch_boolean(
        [manifold3d.Manifold.hull_points(np.asarray(v, dtype=np.float64)) for v, _ in pieces], manifold3d.OpType.Add
    )
    volume = part.volume()
    return float((union - part).volume() / volume), float((part - union).volume() / volume)


def finger_body_hull(finger: trimesh.Trimesh, pad_to_finger: np.ndarray, thickness_mm: float) -> np.ndarray:
    """Vertices (pad frame, mm) of the hull of the finger's material behind the pad's back face.

    Parameters
    ----------
    finger : trimesh.Trimesh
        The finger (finger frame, mm), with or without the pad fused on.
    pad_to_finger : (4, 4) float
        Pad frame to finger frame.
    thickness_mm : float
        Pad thickness T: the back face is u = T.

    Returns
    -------
    (n, 3) float
        Hull vertices; empty when the finger has no material behind the pad.
    """
    in_pad = finger.copy()
    in_pad.apply_transform(np.linalg.inv(pad_to_finger))
    extent = float(np.abs(in_pad.vertices).max()) + 1.0
    behind = to_manifold(in_pad) ^ box((thickness_mm, -extent, -extent), (extent, extent, extent))
    mesh = behind.to_mesh()
    points = np.asarray(mesh.vert_properties[:, :3], dtype=np.float64)
    if len(points) < 4:
        return np.zeros((0, 3))
    return np.asarray(trimesh.convex.convex_hull(points).vertices, dtype=np.float64)
