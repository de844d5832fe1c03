"""Repairing a mesh the way a slicer takes it: closed, oriented shells from an exporter's triangles.

Real print files are often several open or overlapping shells with small
holes, flipped and duplicated triangles. The repair cleans the triangles
(shared corners, no slivers, duplicates resolved with libigl), makes each
shell's winding consistent, closes each open shell's holes with MeshFix
(pymeshfix) and orients every shell outward, or inward where it lies inside
another shell (a void). Overlapping shells stay separate here:
:mod:`fcso.parts` unites them with manifold3d, as it does for any file.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import igl
import numpy as np
import pymeshfix
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from .geometry import volume_about

#: A shell with fewer triangles than a tetrahedron cannot close a volume.
MIN_SHELL_FACES = 4

#: Corners closer than this fraction of the bounding-box diagonal are one
#: corner: exporters round coordinates to float32 (about 1e-7 of the size) and
#: their own arithmetic; 1e-5 is 2 µm on a 200 mm part, far below a printer's resolution.
WELD_TOLERANCE = 1e-5


@dataclass
class RepairSummary:
    """What :func:`repair_shells` changed, in the file's units.

    Attributes
    ----------
    vertices_merged, degenerate_removed, duplicates_removed : int
        Coincident corners merged and open edges' corners stitched; zero-area
        triangles and duplicated triangles (same corners; an opposite pair is
        an internal wall, both go) removed.
    faces_flipped : int
        Triangles whose winding was turned to agree with their shell.
    shells_in, shells_out : int
        Connected shells after cleaning, and closed shells after the repair.
    open_shells : int
        Shells that had holes.
    holes_filled : int
        Boundary loops closed by MeshFix.
    faces_added : int
        Triangles MeshFix added to fill the holes.
    shells_inverted : int
        Inside-out closed shells turned over to face outward.
    shells_dropped : int
        Shells that could not be closed into a volume and were left out.
    volume_before : float
        Sum of the shells' absolute enclosed volumes before hole filling, file units³
        (an open shell's volume is its divergence integral about the centre of
        its open edges' corners, so a flat patch over a hole adds nothing).
    volume_closed : float
        Sum of the closed shells' volumes after hole filling, before overlaps are united, file units³.
    max_deviation : float
        Largest distance from a corner of the repaired mesh to the input triangles, file units.
    volume_after : float
        Volume of the solids made from the repaired shells (overlaps united), file units³;
        set by :mod:`fcso.parts` when it unites them, 0 until then.
    solids_out : int
        Solids made of the repaired shells; set with ``volume_after``.
    lines : list of str
        The changes in words, one line per kind.
    """

    vertices_merged: int = 0
    degenerate_removed: int = 0
    duplicates_removed: int = 0
    faces_flipped: int = 0
    shells_in: int = 0
    shells_out: int = 0
    open_shells: int = 0
    holes_filled: int = 0
    faces_added: int = 0
    shells_inverted: int = 0
    shells_dropped: int = 0
    volume_before: float = 0.0
    volume_closed: float = 0.0
    max_deviation: float = 0.0
    volume_after: float = 0.0
    solids_out: int = 0
    lines: list[str] = field(default_factory=list)

    @property
    def volume_change_percent(self) -> float:
        """How much hole filling and dropped shells changed the shells' volume, % of ``volume_before``.

        Overlaps are not counted: both sums are taken before the union.
        """
        if self.volume_before <= 0:
            return 0.0 if self.volume_closed <= 0 else float("inf")
        return 100.0 * (self.volume_closed - self.volume_before) / self.volume_before


def close_holes_meshfix(shell: trimesh.Trimesh) -> trimesh.Trimesh | None:
    """One open shell with every hole filled by MeshFix (refined fill), or None if it stays open."""
    tmesh = pymeshfix.PyTMesh()
    tmesh.set_quiet(True)
    tmesh.load_array(np.asarray(shell.vertices, dtype=np.float64), np.asarray(shell.faces, dtype=np.int32))
    tmesh.fill_small_boundaries(nbe=0, refine=True)
    vertices, faces = tmesh.return_arrays()
    if len(faces) == 0:
        return None
    closed = trimesh.Trimesh(vertices, faces, process=False)
    closed.merge_vertices()
    return closed


def repair_shells(
    mesh: trimesh.Trimesh, close_holes: Callable[[trimesh.Trimesh], trimesh.Trimesh | None] = close_holes_meshfix
) -> tuple[list[trimesh.Trimesh], RepairSummary]:
    """Make closed, oriented shells from an exporter's triangles.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Any triangles with finite coordinates, in any unit; not changed.
    close_holes : callable
        Closes one consistently wound open shell (None: it cannot); the
        default is MeshFix, others are measured in ``benchmarks.bench_repair``.

    Returns
    -------
    shells : list of trimesh.Trimesh
        The closed shells, each with its own vertices (overlaps not yet
        united); empty when no shell could be closed.
    summary : RepairSummary
        What changed; ``summary.lines`` says it in words.

    Raises
    ------
    ValueError
        No triangles, or NaN or infinite coordinates: no repair mends them.
    """
    # open and flat shells have zero volume: trimesh divides by it for their centre of mass
    with np.errstate(divide="ignore", invalid="ignore"):
        return _repair(mesh, close_holes)


def _repair(
    mesh: trimesh.Trimesh, close_holes: Callable[[trimesh.Trimesh], trimesh.Trimesh | None]
) -> tuple[list[trimesh.Trimesh], RepairSummary]:
    if len(mesh.faces) == 0 or not np.isfinite(mesh.vertices).all():
        # the loader refuses these before any repair (fcso.parts.refuse_unrepairable)
        raise ValueError("repair needs triangles with finite coordinates")
    summary = RepairSummary()
    source = mesh
    mesh = mesh.copy()
    n_vertices = len(mesh.vertices)
    _weld(mesh, WELD_TOLERANCE * float(np.linalg.norm(mesh.extents)))
    summary.vertices_merged = n_vertices - len(mesh.vertices)
    n_faces = len(mesh.faces)
    mesh.update_faces(mesh.nondegenerate_faces())
    summary.degenerate_removed = n_faces - len(mesh.faces)
    # a triangle written twice the same way is kept once; libigl then drops
    # opposite pairs (the wall between two bodies exported as one)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    rotation = (faces.argmin(axis=1)[:, None] + np.arange(3)) % 3
    once = np.unique(np.take_along_axis(faces, rotation, axis=1), axis=0)
    resolved, _ = igl.resolve_duplicated_faces(once)
    summary.duplicates_removed = len(mesh.faces) - len(resolved)
    mesh = trimesh.Trimesh(mesh.vertices, resolved, process=False)
    mesh.remove_unreferenced_vertices()

    closed = []
    shells = mesh.split(only_watertight=False) if len(mesh.faces) else []
    summary.shells_in = len(shells)
    for shell in shells:
        before = shell.faces.copy()
        trimesh.repair.fix_winding(shell)
        flipped = int((shell.faces != before).any(axis=1).sum())
        if 2 * flipped > len(before):
            # keep the winding most of the file's triangles had: an inward shell may be a void
            shell.invert()
            flipped = len(before) - flipped
        summary.faces_flipped += flipped
        if shell.is_watertight:
            summary.volume_before += abs(float(shell.volume))
        else:
            summary.open_shells += 1
            boundary = shell.edges_sorted[trimesh.grouping.group_rows(shell.edges_sorted, require_count=1)]
            summary.volume_before += abs(volume_about(shell, shell.vertices[np.unique(boundary)].mean(axis=0)))
            loops = len(trimesh.graph.connected_components(boundary))
            opened = len(shell.faces)
            shell = close_holes(shell)
            if shell is not None:
                summary.holes_filled += loops
                summary.faces_added += max(len(shell.faces) - opened, 0)
        if shell is None or len(shell.faces) < MIN_SHELL_FACES or not shell.is_watertight or abs(shell.volume) <= 0:
            summary.shells_dropped += 1
            continue
        closed.append(shell)
    _orient(closed, summary)
    summary.shells_out = len(closed)
    summary.volume_closed = sum(abs(float(shell.volume)) for shell in closed)
    if closed:
        squared, _, _ = igl.point_mesh_squared_distance(
            np.ascontiguousarray(np.vstack([shell.vertices for shell in closed]), dtype=np.float64),
            np.ascontiguousarray(source.vertices, dtype=np.float64),
            np.ascontiguousarray(source.faces, dtype=np.int64),
        )
        summary.max_deviation = float(np.sqrt(squared.max()))
    summary.lines = _describe(summary)
    return closed, summary


def _weld(mesh: trimesh.Trimesh, tolerance: float) -> None:
    """Merge coincident corners, then join open edges' corners closer than ``tolerance`` (file units), in place.

    Only corners on open edges move: a slicer stitches gaps, it does not
    collapse a closed surface's small triangles.
    """
    mesh.merge_vertices()
    edges = mesh.edges_sorted
    open_corners = np.unique(edges[trimesh.grouping.group_rows(edges, require_count=1)])
    if len(open_corners) < 2:
        return
    pairs = open_corners[cKDTree(mesh.vertices[open_corners]).query_pairs(tolerance, output_type="ndarray")]
    count = len(mesh.vertices)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(count, count))
    _, labels = connected_components(graph, directed=False)
    _, first = np.unique(labels, return_index=True)
    faces = labels[mesh.faces]
    mesh.vertices = mesh.vertices[first]
    mesh.faces = faces


def _orient(shells: list[trimesh.Trimesh], summary: RepairSummary) -> None:
    """Turn inside-out shells outward; a shell wholly inside another keeps its winding (inward: a void)."""
    for index, shell in enumerate(shells):
        if shell.volume > 0:
            continue
        points = np.ascontiguousarray(shell.vertices, dtype=np.float64)
        enclosed = any(
            (
                np.abs(
                    igl.fast_winding_number(
                        np.ascontiguousarray(other.vertices, dtype=np.float64),
                        np.ascontiguousarray(other.faces, dtype=np.int64),
                        points,
                    )
                )
                > 0.5
            ).all()
            for k, other in enumerate(shells)
            if k != index
        )
        if not enclosed:
            shell.invert()
            summary.shells_inverted += 1


def _describe(summary: RepairSummary) -> list[str]:
    """One line per kind of change, for the report's ``repairs`` list."""
    counts = (
        (summary.vertices_merged, "merged {} duplicate vertices (open edges' corners: closer than 1e-5 of the size)"),
        (summary.degenerate_removed, "removed {} degenerate triangles"),
        (summary.duplicates_removed, "removed {} duplicated triangles"),
        (summary.faces_flipped, "flipped {} triangles to agree with their shell"),
        (
            summary.holes_filled,
            f"filled {{}} holes in {summary.open_shells} open shells with {summary.faces_added} triangles (MeshFix)",
        ),
        (summary.shells_inverted, "turned {} inside-out shells outward"),
        (summary.shells_dropped, "dropped {} shells that enclose no volume"),
    )
    return [text.format(n) for n, text in counts if n]
