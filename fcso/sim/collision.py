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
- the part is split into convex pieces (CoACD) by zones
  (:func:`zoned_pieces`): finely where the pads can reach it, coarsely
  elsewhere. CoACD's time grows with every concavity of the whole part
  (70 s for the 20 mm xyz cube's engraved letters, > 5 min for the solar
  tracker), while only the material the pads can touch decides seating
  and capture; the rest meets only the table and the finger bodies;
- pieces are cached by content hash on disk (shared by candidates, jobs,
  restarts and concurrent workers; written under a name of its own and
  renamed, least recently used entries evicted beyond
  :data:`CACHE_MAX_BYTES`); the fidelity is the volume of the union of
  the pieces against the mesh's own;
- the finger body behind the pad is the convex hull of the finger's
  material behind the pad's back face.

A height field of the pad's face (MuJoCo's ``hfield``) was tried first:
MuJoCo collides it prism by prism of its grid, 10x slower than the pieces
and with hundreds of contacts per step. Boxes over a ``(v, w)`` grid of
column heights, merged where their heights lie on one plane, were tried
for this module: a staircase off the pad by half a cell at every ridge
(the paper cube's median error 0.09 mm against 0.02 mm with the
prisms) and 1000-5000 pieces for the bunny's pad (0.2-0.05 mm cells).
Merging prisms across a convex crease too (a ridge as one piece, the
bunny's pad in 261 pieces instead of 346) made MuJoCo's contacts less
exact: the sanity tests' fingers closed 0.27 mm past their seat.
"""

from __future__ import annotations

import hashlib
import io
import os
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path

import manifold3d
import numpy as np
import trimesh
from scipy.spatial import ConvexHull

from ..geometry import box, to_manifold, to_trimesh

#: Bumped when the decomposition's inputs or method change, so old cache entries are not reused.
CACHE_VERSION = "coacd-4"
#: Largest total size of the decomposition cache, bytes: the least recently used entries go first (an entry is a
#: few kB to a few hundred kB).
CACHE_MAX_BYTES = 500_000_000
#: Largest deviation of the simplified surface CoACD decomposes, mm (see :func:`_decompose`).
SIMPLIFY_TOLERANCE_MM = 0.005


@dataclass
class ConvexPieces:
    """A part as convex pieces.

    Attributes
    ----------
    pieces : list of (vertices (n, 3) float, faces (m, 3) int)
        Convex meshes in the part's frame, mm.
    volume_error : float
        (volume of the union of the pieces - part volume) / part volume.
    missing_fraction : float
        Share of the part's volume not covered by any piece.
    cached : bool
        Whether the pieces came from the cache.
    """

    pieces: list[tuple[np.ndarray, np.ndarray]]
    volume_error: float
    missing_fraction: float
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


def convex_pieces(mesh: trimesh.Trimesh, threshold: float, cache_dir: Path | None) -> ConvexPieces:
    """Convex decomposition of a closed mesh (a part or a fingerpad), cached by content hash.

    A part that is already convex (its hull's volume within 0.1 % of its
    own) is its own hull; otherwise CoACD with the given concavity threshold.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Closed mesh (any frame), mm.
    threshold : float
        CoACD concavity threshold (fraction of the part's size).
    cache_dir : Path or None
        Folder of cached decompositions (created when missing); None: no cache.

    Returns
    -------
    ConvexPieces
    """
    return _cached_pieces(mesh, repr(float(threshold)), lambda: _decompose(mesh, threshold), cache_dir)


def zoned_pieces(
    mesh: trimesh.Trimesh,
    to_zones: np.ndarray,
    fine_boxes: np.ndarray,
    fine_threshold: float,
    coarse_threshold: float,
    cache_dir: Path | None,
) -> ConvexPieces:
    """Convex decomposition of a part, fine inside given boxes and coarse outside, cached by content hash.

    The planes of the boxes' faces cut space into a grid of cells; the
    part's material in each cell is decomposed on its own (CoACD), with
    ``fine_threshold`` in the cells inside a box and ``coarse_threshold``
    elsewhere. Every piece is the hull of material within its (convex) cell,
    so a coarse piece never reaches into a fine box, where the pads act.
    CoACD scales its threshold to each cell's size, so the fine cells are
    also finer in mm than a decomposition of the whole part.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Closed part mesh, mm.
    to_zones : (4, 4) float
        The mesh's frame to the boxes' frame.
    fine_boxes : (k, 2, 3) float
        Lower and upper corners of the boxes (boxes' frame, mm).
    fine_threshold, coarse_threshold : float
        CoACD concavity thresholds inside and outside the boxes.
    cache_dir : Path or None
        Folder of cached decompositions; None: no cache.

    Returns
    -------
    ConvexPieces
        Pieces in the mesh's frame.
    """
    to_zones = np.asarray(to_zones, dtype=np.float64)
    fine_boxes = np.asarray(fine_boxes, dtype=np.float64).reshape(-1, 2, 3)
    settings = (
        f"zoned {float(fine_threshold)!r} {float(coarse_threshold)!r} "
        f"{np.round(to_zones, 6).tolist()} {np.round(fine_boxes, 4).tolist()}"
    )
    return _cached_pieces(
        mesh,
        settings,
        lambda: _zoned(mesh, to_zones, fine_boxes, fine_threshold, coarse_threshold, cache_dir),
        cache_dir,
    )


def _zoned(
    mesh, to_zones, fine_boxes, fine_threshold, coarse_threshold, cache_dir
) -> list[tuple[np.ndarray, np.ndarray]]:
    moved = mesh.copy()
    moved.apply_transform(to_zones)
    part = to_manifold(moved)
    lower, upper = moved.bounds[0] - 1.0, moved.bounds[1] + 1.0
    # the grid's planes: the boxes' faces inside the part's bounds
    planes = [
        np.unique(
            np.clip(
                np.concatenate([[lower[axis], upper[axis]], fine_boxes[:, :, axis].ravel()]), lower[axis], upper[axis]
            )
        )
        for axis in range(3)
    ]
    back = np.linalg.inv(to_zones)
    pieces = []
    for i, j, k in np.ndindex(*(len(p) - 1 for p in planes)):
        cell_lower = np.array([planes[0][i], planes[1][j], planes[2][k]])
        cell_upper = np.array([planes[0][i + 1], planes[1][j + 1], planes[2][k + 1]])
        centre = (cell_lower + cell_upper) / 2.0
        fine = bool(np.any(np.all((fine_boxes[:, 0] <= centre) & (centre <= fine_boxes[:, 1]), axis=1)))
        material = part ^ box(cell_lower, cell_upper)
        if material.is_empty():
            continue
        for component in material.decompose():
            if component.volume() < 1e-6:
                continue
            threshold = fine_threshold if fine else coarse_threshold
            for vertices, faces in _cell_pieces(to_trimesh(component), threshold, cache_dir):
                pieces.append((vertices @ back[:3, :3].T + back[:3, 3], faces))
    return pieces


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
    it out: the carved pocket is first swept towards ``-u``. The volume
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
    return _cached_pieces(pad, f"prisms {float(thickness_mm)!r}", lambda: _prisms(pad, thickness_mm), cache_dir)


def _prisms(pad: trimesh.Trimesh, thickness_mm: float) -> list[tuple[np.ndarray, np.ndarray]]:
    solid = to_manifold(pad).simplify(SIMPLIFY_TOLERANCE_MM)
    lower, upper = np.asarray(solid.bounding_box()[:3]), np.asarray(solid.bounding_box()[3:])
    front, back = min(0.0, float(lower[0])) - 1.0, max(float(thickness_mm), float(upper[0]))
    region = box((front, lower[1], lower[2]), (back, upper[1], upper[2]))
    # the carved pocket swept towards -u (the union of each of its triangles' sweeps): what the columns leave out
    pocket = (region - solid).to_mesh64()
    triangles = np.asarray(pocket.vert_properties[:, :3], dtype=np.float64)[np.asarray(pocket.tri_verts)]
    sweeps = []
    for triangle in triangles:
        swept = manifold3d.Manifold.hull_points(np.vstack([triangle, triangle - [back - front, 0.0, 0.0]]))
        if swept.volume() > 1e-12:
            sweeps.append(swept)
    columns = region - manifold3d.Manifold.batch_boolean(sweeps, manifold3d.OpType.Add) if sweeps else region
    face = columns.simplify(SIMPLIFY_TOLERANCE_MM).to_mesh64()
    vertices = np.asarray(face.vert_properties[:, :3], dtype=np.float64)
    corners = np.asarray(face.tri_verts, dtype=np.int64)
    normals = np.cross(
        vertices[corners[:, 1]] - vertices[corners[:, 0]], vertices[corners[:, 2]] - vertices[corners[:, 0]]
    )
    # material is entered along +u through the triangles facing -u (twice their shadow's area, mm^2); walls have none
    corners, normals = corners[-normals[:, 0] > 2e-6], normals[-normals[:, 0] > 2e-6]
    pieces = []
    for cluster in _convex_clusters(vertices, corners, normals / np.linalg.norm(normals, axis=1, keepdims=True)):
        top = vertices[np.unique(corners[cluster])]
        behind = top.copy()
        behind[:, 0] = back
        prism = manifold3d.Manifold.hull_points(np.vstack([top, behind])).to_mesh64()
        pieces.append(
            (np.asarray(prism.vert_properties[:, :3], dtype=np.float64), np.asarray(prism.tri_verts, dtype=np.int64))
        )
    return pieces


def _convex_clusters(vertices: np.ndarray, corners: np.ndarray, normals: np.ndarray) -> list[list[int]]:
    """Triangles of a surface grouped into coplanar, edge-connected clusters whose shadow on ``u = 0`` is convex.

    Greedy: a cluster grows from its first triangle by neighbours of the
    same plane while the hull of its shadow has the area of its triangles'
    shadows. The prism under such a cluster is convex; a flat face or a
    planar wall of a pocket is one piece instead of one per triangle.
    """
    first, second = (vertices[corners[:, k], 1:] - vertices[corners[:, 0], 1:] for k in (1, 2))
    shadow_area = np.abs(first[:, 0] * second[:, 1] - first[:, 1] * second[:, 0]) / 2.0
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
        cluster, area = [seed], float(shadow_area[seed])
        frontier = [t for t in adjacent[seed] if normals[t] @ normals[seed] > 1.0 - 1e-9]
        while frontier:
            candidate = frontier.pop()
            if taken[candidate]:
                continue
            points = vertices[np.unique(corners[cluster + [candidate]]), 1:]
            grown = area + float(shadow_area[candidate])
            if ConvexHull(points).volume <= grown * (1.0 + 1e-9) + 1e-9:
                taken[candidate] = True
                cluster.append(candidate)
                area = grown
                frontier.extend(
                    t for t in adjacent[candidate] if not taken[t] and normals[t] @ normals[seed] > 1.0 - 1e-9
                )
        clusters.append(cluster)
    return clusters


def _cell_pieces(
    material: trimesh.Trimesh, threshold: float, cache_dir: Path | None
) -> list[tuple[np.ndarray, np.ndarray]]:
    """CoACD pieces of the material in one cell of :func:`zoned_pieces`, cached on their own: a refinement of the
    fine cells (:func:`fcso.sim.verify.fitted_pieces`) reuses the coarse cells' pieces instead of making them again.
    """
    if cache_dir is None:
        return _decompose(material, threshold)
    key = mesh_key(np.asarray(material.vertices), np.asarray(material.faces), f"cell {float(threshold)!r}")
    path = Path(cache_dir) / f"{key}.npz"
    pieces = _read_cached(path)
    if pieces is None:
        pieces = _decompose(material, threshold)
        _write_cached(path, _write_pieces(pieces))
    return pieces


def _cached_pieces(mesh: trimesh.Trimesh, settings: str, decompose, cache_dir: Path | None) -> ConvexPieces:
    """Pieces from the cache (key: the mesh and ``settings``) or from ``decompose()``, with their volume errors."""
    key = mesh_key(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64), settings)
    path = None if cache_dir is None else Path(cache_dir) / f"{key}.npz"
    pieces = None if path is None else _read_cached(path)
    cached = pieces is not None
    if pieces is None:
        pieces = decompose()
        if path is not None:
            _write_cached(path, _write_pieces(pieces))
    excess, missing = union_volume_errors(mesh, pieces)
    return ConvexPieces(pieces=pieces, volume_error=excess - missing, missing_fraction=missing, cached=cached)


def _read_cached(path: Path) -> list[tuple[np.ndarray, np.ndarray]] | None:
    """A cache entry's pieces, or None when it is absent or unreadable (then it is made again).

    Reading marks the entry as used (its modification time), so the
    eviction of :func:`_write_cached` removes the least recently used.
    """
    try:
        pieces = _read_pieces(path.read_bytes())
        os.utime(path)
        return pieces
    except (OSError, ValueError, KeyError, zipfile.BadZipFile):
        # absent, or removed by another worker's eviction between the two calls
        return None


def _write_cached(path: Path, data: bytes) -> None:
    """Write a cache entry under a name of its own, rename it into place, then keep the cache within its size.

    Several workers may write the same entry at once: each renames a whole
    file of identical content, so a reader never sees a part of one. A
    cache that cannot be written (full disk, read-only) costs time only.
    """
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, prefix=f".{path.stem}.", suffix=".tmp", delete=False) as f:
            f.write(data)
        os.replace(f.name, path)
    except OSError:
        return
    evict(path.parent, CACHE_MAX_BYTES)


def evict(cache_dir: Path, max_bytes: int) -> None:
    """Remove the least recently used entries until the cache holds at most ``max_bytes``.

    Parameters
    ----------
    cache_dir : Path
        The cache folder (its ``*.npz`` entries).
    max_bytes : int
        Largest total size of the entries, bytes.
    """
    entries = []
    for entry in Path(cache_dir).glob("*.npz"):
        try:
            stat = entry.stat()
        except OSError:
            continue
        entries.append((stat.st_mtime, stat.st_size, entry))
    total = sum(size for _, size, _ in entries)
    for _, size, entry in sorted(entries, key=lambda e: e[0]):
        if total <= max_bytes:
            break
        entry.unlink(missing_ok=True)
        total -= size


def _decompose(mesh: trimesh.Trimesh, threshold: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """CoACD pieces of a closed mesh, or its hull when it is convex.

    The mesh is first simplified within :data:`SIMPLIFY_TOLERANCE_MM`
    (manifold3d): a pad carved with a print clearance and lead-in has ~35k
    triangles of offset surface, on which CoACD took 14 s (190 s at a
    quarter of the threshold); simplified to ~400 triangles, 1.3 s for the
    same pieces. The fidelity is measured against the unsimplified mesh.
    """
    hull = mesh.convex_hull
    if hull.volume <= mesh.volume * 1.001:
        return [(np.asarray(hull.vertices, dtype=np.float64), np.asarray(hull.faces, dtype=np.int64))]
    import coacd

    mesh = to_trimesh(to_manifold(mesh).simplify(SIMPLIFY_TOLERANCE_MM))

    coacd.set_log_level("error")
    # no preprocessing: our meshes are already closed manifolds, and CoACD's
    # voxel remeshing inflated every piece by 0.3-0.8 mm (a carved pad's
    # ridge then stalled on the part's pieces mm before its seat); coarser
    # search settings than the defaults: 2-5x faster for the same pieces
    result = coacd.run_coacd(
        coacd.Mesh(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)),
        threshold=threshold,
        preprocess_mode="off",
        resolution=1000,
        mcts_iterations=60,
        mcts_nodes=10,
        seed=0,
    )
    pieces = []
    for piece_vertices, piece_faces in result:
        if len(piece_vertices) < 4:
            continue
        piece = trimesh.Trimesh(piece_vertices, piece_faces, process=True).convex_hull
        if piece.volume > 1e-6:
            pieces.append((np.asarray(piece.vertices, dtype=np.float64), np.asarray(piece.faces, dtype=np.int64)))
    return pieces


def _write_pieces(pieces) -> bytes:
    buffer = io.BytesIO()
    arrays = {}
    for k, (v, f) in enumerate(pieces):
        arrays[f"v{k}"], arrays[f"f{k}"] = v, f
    np.savez_compressed(buffer, count=len(pieces), **arrays)
    return buffer.getvalue()


def _read_pieces(data: bytes) -> list[tuple[np.ndarray, np.ndarray]]:
    with np.load(io.BytesIO(data)) as stored:
        return [(stored[f"v{k}"], stored[f"f{k}"]) for k in range(int(stored["count"]))]


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
