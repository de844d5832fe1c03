"""Loading part and finger meshes: formats, units, validation and explicit repair."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from .errors import MeshError

#: Length of one unit in millimetres.
UNIT_MM = {"mm": 1.0, "inch": 25.4, "m": 1000.0}

#: File endings trimesh reads that fcso accepts.
MESH_SUFFIXES = (".stl", ".3mf", ".obj", ".ply", ".dae")


@dataclass
class Part:
    """A validated closed mesh in millimetres.

    Attributes
    ----------
    name : str
        File stem, used in reports.
    path : str
        Where it was read from.
    mesh : trimesh.Trimesh
        Watertight, positive-volume mesh in mm.
    scale : float
        Factor applied to the file's coordinates to get mm.
    repairs : list of str
        What ``repair=True`` changed, empty when nothing was repaired.
    """

    name: str
    path: str
    mesh: trimesh.Trimesh
    scale: float = 1.0
    repairs: list[str] = field(default_factory=list)


def unit_factor(units: str | float, source: str | Path = "units") -> float:
    """Millimetres per file unit for ``'mm'``, ``'inch'``, ``'m'`` or a positive number."""
    if isinstance(units, str):
        if units in UNIT_MM:
            return UNIT_MM[units]
        try:
            units = float(units)
        except ValueError:
            raise MeshError(source, f"unknown unit {units!r} (use mm, inch, m or a factor)") from None
    factor = float(units)
    if not np.isfinite(factor) or factor <= 0:
        raise MeshError(source, f"unit factor must be a positive number, got {units!r}")
    return factor


def read_mesh(path: str | Path) -> trimesh.Trimesh:
    """Read a mesh file into one :class:`trimesh.Trimesh` without changing it.

    Raises
    ------
    MeshError
        Missing file, unsupported ending, or a file trimesh cannot parse
        (truncated or malformed).
    """
    path = Path(path)
    if not path.is_file():
        raise MeshError(path, "file not found")
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise MeshError(path, f"unsupported file type {suffix!r} (use {', '.join(MESH_SUFFIXES)})")
    if suffix == ".stl":
        _check_stl_size(path)
    try:
        loaded = trimesh.load(str(path), force="mesh", process=False)
        # STL stores every triangle's corners separately: sharing them is
        # reading the file, not repairing it
        loaded.merge_vertices()
    except Exception as exc:  # trimesh raises many types for malformed files
        raise MeshError(path, f"cannot be read as {suffix[1:].upper()}: {exc}") from None
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise MeshError(path, "empty mesh: no triangles")
    return loaded


def _check_stl_size(path: Path) -> None:
    """Refuse a binary STL whose length disagrees with its triangle count (truncated)."""
    data = path.read_bytes()
    if data[:5].lower() == b"solid" and b"facet" in data[:1024]:
        if b"endsolid" not in data[-1024:]:
            raise MeshError(path, "truncated ASCII STL: no 'endsolid' at the end")
        return
    if len(data) < 84:
        raise MeshError(path, f"truncated STL: {len(data)} bytes, shorter than the 84-byte header")
    count = int(np.frombuffer(data[80:84], dtype="<u4")[0])
    expected = 84 + 50 * count
    if len(data) < expected:
        raise MeshError(
            path, f"truncated binary STL: header announces {count} triangles ({expected} bytes), file has {len(data)} bytes"
        )


def mesh_defects(mesh: trimesh.Trimesh) -> list[str]:
    """Defects that stop a mesh from being a closed, oriented volume; empty list if none."""
    if len(mesh.faces) == 0:
        return ["empty mesh: no triangles"]
    if not np.all(np.isfinite(mesh.vertices)):
        return [f"non-finite coordinates (NaN or infinity) in {int((~np.isfinite(mesh.vertices)).any(axis=1).sum())} vertices"]
    defects = []
    merged = mesh.copy()
    merged.merge_vertices()
    if not merged.is_watertight:
        _, counts = np.unique(merged.edges_sorted, axis=0, return_counts=True)
        boundary, shared = int((counts == 1).sum()), int((counts > 2).sum())
        what = ", ".join(
            text for n, text in ((boundary, f"{boundary} boundary edges"), (shared, f"{shared} edges shared by more than two triangles")) if n
        ) or "degenerate triangles"
        defects.append(f"open mesh: not watertight ({what})")
    elif not merged.is_winding_consistent:
        defects.append("inconsistent triangle winding")
    else:
        volume = merged.volume
        if not np.isfinite(volume) or abs(volume) < 1e-9 * max(merged.extents.max(), 1e-12) ** 3:
            defects.append("zero volume")
        elif volume < 0:
            defects.append("inside-out: negative volume (normals point inwards)")
    return defects


def repair_mesh(mesh: trimesh.Trimesh) -> tuple[trimesh.Trimesh, list[str]]:
    """Repair what can be repaired without changing the shape.

    Merges duplicate vertices, drops degenerate and duplicate triangles,
    makes winding consistent and outward, fills simple holes.

    Returns
    -------
    mesh : trimesh.Trimesh
        The repaired copy.
    changes : list of str
        One line per change made.
    """
    mesh = mesh.copy()
    changes = []
    finite = np.isfinite(mesh.vertices).all(axis=1)
    if not finite.all():
        keep = finite[mesh.faces].all(axis=1)
        changes.append(f"removed {int((~keep).sum())} triangles with non-finite vertices")
        mesh.update_faces(keep)
        mesh.remove_unreferenced_vertices()
    n_vertices = len(mesh.vertices)
    mesh.merge_vertices()
    if len(mesh.vertices) != n_vertices:
        changes.append(f"merged {n_vertices - len(mesh.vertices)} duplicate vertices")
    n_faces = len(mesh.faces)
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.update_faces(mesh.unique_faces())
    mesh.remove_unreferenced_vertices()
    if len(mesh.faces) != n_faces:
        changes.append(f"removed {n_faces - len(mesh.faces)} degenerate or duplicate triangles")
    if not mesh.is_watertight:
        n_faces = len(mesh.faces)
        trimesh.repair.fill_holes(mesh)
        if len(mesh.faces) != n_faces:
            changes.append(f"filled holes with {len(mesh.faces) - n_faces} triangles")
    volume_before = mesh.volume if mesh.is_watertight else None
    winding_before = mesh.is_winding_consistent
    trimesh.repair.fix_normals(mesh, multibody=True)
    if not winding_before and mesh.is_winding_consistent:
        changes.append("made triangle winding consistent")
    if volume_before is not None and volume_before < 0 < mesh.volume:
        changes.append("flipped inside-out mesh")
    return mesh, changes


def validate_mesh(mesh: trimesh.Trimesh, path: str | Path, repair: bool = False) -> tuple[trimesh.Trimesh, list[str]]:
    """Check that ``mesh`` is a closed, oriented volume; repair first if asked.

    Raises
    ------
    MeshError
        Naming ``path`` and the first defect (after repair, if it was asked for).
    """
    changes: list[str] = []
    if len(mesh.faces) == 0:
        raise MeshError(path, "empty mesh: no triangles")
    if repair:
        mesh, changes = repair_mesh(mesh)
    defects = mesh_defects(mesh)
    if defects:
        hint = " even after --repair" if repair else " (run with --repair to try to fix it)"
        raise MeshError(path, defects[0] + hint)
    mesh = mesh.copy()
    mesh.merge_vertices()
    return mesh, changes


def load_part(
    path: str | Path,
    units: str | float = "mm",
    scale_to_mm: float | None = None,
    repair: bool = False,
    name: str | None = None,
) -> Part:
    """Load a part mesh and check it is a closed, positive-volume solid.

    Parameters
    ----------
    path : str or Path
        STL, 3MF, OBJ, PLY (or DAE) file.
    units : {'mm', 'inch', 'm'} or float
        Unit of the file's coordinates, or a factor to millimetres.
    scale_to_mm : float, optional
        Scale uniformly so that the longest bounding-box side is this long (mm),
        applied after ``units``.
    repair : bool
        Try :func:`repair_mesh` before validating; what changed is kept in
        :attr:`Part.repairs`.
    name : str, optional
        Name in reports; default the file stem.

    Returns
    -------
    Part

    Raises
    ------
    MeshError
        Naming the file and the defect.
    """
    path = Path(path)
    mesh = read_mesh(path)
    factor = unit_factor(units, path)
    if not np.all(np.isfinite(mesh.vertices)) and not repair:
        raise MeshError(path, mesh_defects(mesh)[0])
    mesh, changes = validate_mesh(mesh, path, repair=repair)
    if scale_to_mm is not None:
        if not scale_to_mm > 0:
            raise MeshError(path, f"scale-to length must be positive, got {scale_to_mm}")
        factor = scale_to_mm / float(mesh.extents.max())
    mesh.apply_scale(factor)
    return Part(name=name or path.stem, path=str(path), mesh=mesh, scale=factor, repairs=changes)
