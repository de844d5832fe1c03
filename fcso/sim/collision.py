"""Collision geometry that keeps concavities, and its fidelity (METHOD §12).

MuJoCo collides a mesh by its convex hull, so

- the part and the carved fingerpad are each split into convex pieces
  (CoACD), cached by content hash on disk (shared by candidates, jobs,
  restarts and concurrent workers; written under a name of its own and
  renamed, least recently used entries evicted beyond
  :data:`CACHE_MAX_BYTES`); the fidelity is the volume of the union of
  the pieces against the mesh's own;
- a part is decomposed by zones (:func:`zoned_pieces`): finely where the
  pads can reach it, coarsely elsewhere. CoACD's time grows with every
  concavity of the whole part (70 s for the 20 mm xyz cube's engraved
  letters, > 5 min for the solar tracker), while only the material the
  pads can touch decides seating and capture; the rest meets only the
  table and the finger bodies;
- the finger body behind the pad is the convex hull of the finger's
  material behind the pad's back face.

A height field of the pad's face (exact for a pad approaching along its
thickness, and derived from the pad's structure) was tried first: MuJoCo
collides it prism by prism, 10x slower than the pieces and with hundreds
of contacts per step.
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

from ..geometry import box, to_manifold, to_trimesh
from ..screen import ScreenGrid, column_heights

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
        mesh, settings, lambda: _zoned(mesh, to_zones, fine_boxes, fine_threshold, coarse_threshold), cache_dir
    )


def _zoned(mesh, to_zones, fine_boxes, fine_threshold, coarse_threshold) -> list[tuple[np.ndarray, np.ndarray]]:
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
            for vertices, faces in _decompose(to_trimesh(component), fine_threshold if fine else coarse_threshold):
                pieces.append((vertices @ back[:3, :3].T + back[:3, 3], faces))
    return pieces


def pad_column_pieces(
    pad: trimesh.Trimesh,
    pad_size_mm: tuple[float, float, float],
    cell_mm: float,
    flatness_mm: float,
    max_slope: float,
    cache_dir: Path | None,
) -> ConvexPieces:
    """Convex pieces of a carved pad from its column heights over a ``(v, w)`` grid, cached by content hash.

    The pad is ``P = {u >= H(v, w)}`` in its box ``[0, T] x [0, L] x [0, W]``
    (METHOD §8b's columns): ``H`` at each cell centre is where the ray along
    ``+u`` last enters the pad's material, so material the part overhangs
    (which the design's screening drops too) is left out. Neighbouring
    cells whose heights lie on one plane (within ``flatness_mm``, rising
    at most ``max_slope`` mm per mm) are merged, greedily into rectangles,
    and each rectangle is the convex slab between that plane and the back
    face: flat and gently sloping faces are exact, with a few pieces; a
    steep wall is a staircase of cells, off the pad's wall by at most half
    a cell across it. No decomposition is searched: a pad takes well under
    a second.

    Parameters
    ----------
    pad : trimesh.Trimesh
        The carved pad, pad frame, mm.
    pad_size_mm : (T, L, W)
    cell_mm : float
        Grid cell, mm.
    flatness_mm : float
        Largest distance (along ``u``) of a merged cell's height from its rectangle's plane, mm.
    max_slope : float
        Steepest plane a rectangle of several cells may have (``|dH/dv|`` and ``|dH/dw|``).
    cache_dir : Path or None
        Folder of cached pieces; None: no cache.

    Returns
    -------
    ConvexPieces
        Pieces in the pad frame.
    """
    settings = f"columns {list(map(float, pad_size_mm))} {float(cell_mm)!r} {float(flatness_mm)!r} {float(max_slope)!r}"
    return _cached_pieces(pad, settings, lambda: _columns(pad, pad_size_mm, cell_mm, flatness_mm, max_slope), cache_dir)


def pad_heights(pad: trimesh.Trimesh, grid: ScreenGrid) -> np.ndarray:
    """``H`` of a pad at every cell centre: where the ray along ``+u`` last enters its material, mm.

    Returns
    -------
    (count_v, count_w) float
        mm; ``-inf`` where the ray meets no material (a hole through the pad).
    """
    vertices, faces = np.asarray(pad.vertices, dtype=np.float64), np.asarray(pad.faces, dtype=np.int64)
    # the surface where a ray along +u enters material faces -u; its top on the ray is the last entry
    entering = np.asarray(pad.face_normals)[:, 0] < 0.0
    heights = column_heights(vertices, faces[entering], grid, empty=-np.inf)
    return heights.astype(np.float64).reshape(grid.count_v, grid.count_w)


def _columns(pad, pad_size_mm, cell_mm, flatness_mm, max_slope) -> list[tuple[np.ndarray, np.ndarray]]:
    thickness, length, width = (float(x) for x in pad_size_mm)
    grid = ScreenGrid(float(cell_mm), max(1, int(np.ceil(length / cell_mm))), max(1, int(np.ceil(width / cell_mm))))
    heights = pad_heights(pad, grid)
    open_cells = np.isfinite(heights) & (heights < thickness - 1e-6)
    centre_v = (np.arange(grid.count_v) + 0.5) * cell_mm
    centre_w = (np.arange(grid.count_w) + 0.5) * cell_mm

    def plane(j0: int, j1: int, k0: int, k1: int) -> tuple[float, float, float] | None:
        """``(a, b, c)`` of ``H = a + b v + c w`` through the rectangle's cells, or None when they are not on one."""
        if not open_cells[j0:j1, k0:k1].all():
            return None
        block = heights[j0:j1, k0:k1]
        low, high = float(block.min()), float(block.max())
        if high - low <= 2.0 * flatness_mm:
            return ((low + high) / 2.0, 0.0, 0.0)
        # least squares on a full rectangle of centres: the centred v and w are orthogonal, so each slope is its own
        dv, dw = centre_v[j0:j1] - centre_v[j0:j1].mean(), centre_w[k0:k1] - centre_w[k0:k1].mean()
        a = float(block.mean())
        b = float(dv @ block.sum(axis=1) / (block.shape[1] * (dv @ dv))) if j1 - j0 > 1 else 0.0
        c = float(block.sum(axis=0) @ dw / (block.shape[0] * (dw @ dw))) if k1 - k0 > 1 else 0.0
        if max(abs(b), abs(c)) > max_slope or np.abs(block - a - b * dv[:, None] - c * dw[None, :]).max() > flatness_mm:
            return None
        v_mid, w_mid = float(centre_v[j0:j1].mean()), float(centre_w[k0:k1].mean())
        return (float(a - b * v_mid - c * w_mid), float(b), float(c))

    pieces = []
    for j, k in zip(*np.nonzero(open_cells)):
        if not open_cells[j, k]:
            continue  # taken by an earlier rectangle
        fit = plane(j, j + 1, k, k + 1)
        k_end = k + 1
        while k_end < grid.count_w and (wider := plane(j, j + 1, k, k_end + 1)) is not None:
            fit, k_end = wider, k_end + 1
        j_end = j + 1
        while j_end < grid.count_v and (longer := plane(j, j_end + 1, k, k_end)) is not None:
            fit, j_end = longer, j_end + 1
        floor = float(heights[j:j_end, k:k_end].min())
        open_cells[j:j_end, k:k_end] = False
        piece = _slab(
            fit,
            floor,
            thickness,
            (j * cell_mm, min(j_end * cell_mm, length)),
            (k * cell_mm, min(k_end * cell_mm, width)),
        )
        if piece is not None:
            pieces.append(piece)
    return pieces


def _slab(fit, floor_mm, thickness_mm, v_range, w_range) -> tuple[np.ndarray, np.ndarray] | None:
    """The convex piece ``{u >= max(a + b v + c w, floor), u <= T}`` over a rectangle of ``(v, w)``, or None.

    The floor keeps a sloping plane, extrapolated half a cell beyond the
    rectangle's outer cell centres, from reaching below the lowest of its
    heights (into a pocket beside it).
    """
    a, b, c = fit
    normal = np.array([1.0, -b, -c])
    norm = float(np.linalg.norm(normal))
    solid = box((floor_mm, v_range[0], w_range[0]), (thickness_mm, v_range[1], w_range[1]))
    solid = solid.trim_by_plane((normal / norm).tolist(), a / norm)
    if solid.is_empty() or solid.volume() < 1e-9:
        return None
    mesh = solid.to_mesh64()
    return np.asarray(mesh.vert_properties[:, :3], dtype=np.float64), np.asarray(mesh.tri_verts, dtype=np.int64)


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
