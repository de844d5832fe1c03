"""Exact gaps between placed solids (manifold3d's ``min_gap``), the check of every position the voxel search
chooses and the nearest neighbours the placement report tells. Lengths are millimetres.
"""

from __future__ import annotations

from collections.abc import Sequence

import manifold3d
import numpy as np
import trimesh

from .build3mf import BuildItem
from .models import BuildConfig, PlacedItemReport

#: Exact gaps are taken this much smaller when checked against the spacing:
#: the rounding of the meshes' vertices in manifold3d.
GAP_TOLERANCE_MM = 1e-3


def solid_manifold(mesh: trimesh.Trimesh) -> manifold3d.Manifold:
    """The mesh as a manifold3d solid, for exact gaps; the mesh must be closed."""
    return manifold3d.Manifold(
        manifold3d.Mesh64(
            vert_properties=np.ascontiguousarray(mesh.vertices, dtype=np.float64),
            tri_verts=np.ascontiguousarray(mesh.faces, dtype=np.uint64),
        )
    )


def mesh_gap(a: manifold3d.Manifold, b: manifold3d.Manifold, limit_mm: float) -> float:
    """Exact gap between two solids, 0 when they touch, overlap or nest; at most ``limit_mm``."""
    return float(a.min_gap(b, float(limit_mm)))


def bounds_gap(a: np.ndarray, b: np.ndarray) -> float:
    """Gap between two axis-aligned boxes ((2, 3) each); 0 when they overlap."""
    separation = np.maximum(0.0, np.maximum(a[0] - b[1], b[0] - a[1]))
    return float(np.linalg.norm(separation))


def bounds_span(a: np.ndarray, b: np.ndarray) -> float:
    """Largest distance between a point of box ``a`` and one of box ``b``."""
    return float(np.linalg.norm(np.maximum(a[1], b[1]) - np.minimum(a[0], b[0])))


def placed_vertices(item: BuildItem) -> np.ndarray:
    """An item's vertices moved by its transform, (n, 3) mm."""
    return item.mesh.vertices @ item.transform[:3, :3].T + item.transform[:3, 3]


def vertex_bounds(vertices: np.ndarray) -> np.ndarray:
    """[[xmin, ymin, zmin], [xmax, ymax, zmax]] of points (n, 3)."""
    return np.array([vertices.min(axis=0), vertices.max(axis=0)])


def placed_solid(solid: manifold3d.Manifold, transform: np.ndarray) -> manifold3d.Manifold:
    """A manifold3d solid moved by a 4x4 transform."""
    return solid.transform(np.ascontiguousarray(transform[:3, :4], dtype=np.float64))


def clear_of(
    bounds: np.ndarray,
    solid: manifold3d.Manifold,
    others: Sequence[tuple[np.ndarray, manifold3d.Manifold]],
    spacing: float,
) -> bool:
    """True when ``solid`` is at least ``spacing`` from every solid of ``others`` (exact check; boxes skip the far
    ones).
    """
    for other_bounds, other in others:
        if bounds_gap(bounds, other_bounds) >= spacing:
            continue
        if mesh_gap(solid, other, spacing + 1.0) < spacing + GAP_TOLERANCE_MM:
            return False
    return True


def nearest_neighbours(
    bounds: Sequence[np.ndarray], solids: Sequence[manifold3d.Manifold]
) -> list[tuple[float | None, int | None]]:
    """Each solid's gap to its nearest other solid and that solid's index.

    Candidates go by bounding-box gap; each exact gap is searched no further
    than the nearest gap found so far, and the search stops at the first box
    farther than that.
    """
    gaps: dict[tuple[int, int], float] = {}
    nearest = []
    for i in range(len(solids)):
        order = sorted((bounds_gap(bounds[i], bounds[j]), j) for j in range(len(solids)) if j != i)
        best, best_index = np.inf, None
        for box_gap, j in order:
            if box_gap >= best:
                break
            pair = (min(i, j), max(i, j))
            if pair in gaps:
                gap = gaps[pair]
            else:
                # min_gap slows down with its search length: search just past
                # the boxes' gap first, widening until found or beyond best
                limit = min(best, bounds_span(bounds[i], bounds[j]) + 1.0)
                search = min(box_gap + 1.0, limit)
                gap = mesh_gap(solids[i], solids[j], search)
                while gap >= search and search < limit:
                    search = min(2.0 * search, limit)
                    gap = mesh_gap(solids[i], solids[j], search)
                # a gap at the limit is only a lower bound, not worth keeping
                if gap < limit:
                    gaps[pair] = gap
            if gap < best:
                best, best_index = gap, j
        nearest.append((None, None) if best_index is None else (float(best), best_index))
    return nearest


def placed_item_reports(
    items: Sequence[BuildItem], fixed_ids: set[int], solids: dict[int, manifold3d.Manifold], config: BuildConfig
) -> tuple[list[PlacedItemReport], list[str]]:
    """Each placed item's report (its bounds and nearest neighbour) and the warnings of items outside the build
    volume minus the wall margin, or of the job's own items (``fixed_ids``: by ``id``) closer than the spacing.

    Parameters
    ----------
    items : sequence of BuildItem
        Every item with its transform.
    fixed_ids : set of int
        ``id`` of the items the job's build placed.
    solids : dict
        manifold3d solid of every mesh in its own frame, by ``id(mesh)``.
    config : BuildConfig
    """
    bounds_list = [vertex_bounds(placed_vertices(item)) for item in items]
    nearest = nearest_neighbours(bounds_list, [placed_solid(solids[id(item.mesh)], item.transform) for item in items])
    lower = np.array(config.origin_mm)
    upper = lower + np.array(config.volume_mm)
    reports, warnings = [], []
    for item, bounds, (distance, neighbour) in zip(items, bounds_list, nearest):
        if np.any(bounds[0] < lower + config.wall_margin_mm - 1e-6) or np.any(
            bounds[1] > upper - config.wall_margin_mm + 1e-6
        ):
            warnings.append(f"{item.name} lies outside the build volume minus the wall margin")
        if distance is not None and distance < config.spacing_mm - GAP_TOLERANCE_MM and id(item) in fixed_ids:
            warnings.append(
                f"{item.name} is {distance:.2f} mm from {items[neighbour].name}, closer than spacing_mm in the job's "
                f"build"
            )
        reports.append(
            PlacedItemReport(
                name=item.name,
                kind=item.kind,
                placed_by="build" if id(item) in fixed_ids else "placer",
                transform=np.asarray(item.transform).tolist(),
                bounds_mm=bounds.tolist(),
                nearest_distance_mm=None if distance is None else round(distance, 3),
                nearest_item=None if neighbour is None else items[neighbour].name,
            )
        )
    return reports, warnings
