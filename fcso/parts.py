"""Loading part and finger meshes: formats, units, validation, shells and explicit repair.

One loader serves ``fcso design`` and ``fcsod``: a plain mesh file is one
mesh, a 3MF is its build items (each object once, with the transforms of the
items that place it). Each mesh is then split into solids the way a slicer
prints it (:mod:`fcso.solids`), and separate solids are separate parts.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from .errors import MeshError, RepairToleranceError
from .repair import RepairSummary, repair_shells
from .solids import Solid, mesh_solids, unite_shells
from .threemf import MAX_3MF_UNCOMPRESSED_BYTES, MeshItem, read_3mf_items

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
    repair : RepairSummary or None
        The counts behind ``repairs`` (file units; ``scale`` converts), None without ``repair=True``.
    shells : int
        Closed shells of the file's mesh that make up this part.
    solid_index : int or None
        ``k`` of the name ``<file>#<k>`` when the file held several separate
        solids (1 = the largest), else None.
    shell_note : str or None
        How the shells were made one solid, in words; None for one shell.
    warnings : list of str
        What a user should know about how the file was read.
    instances : list of (4, 4) float or None
        Transforms (mesh frame to build frame, mm) of the file's build items
        that hold this part: one per 3MF item, ``[None]`` for a plain mesh file.
    """

    name: str
    path: str
    mesh: trimesh.Trimesh
    scale: float = 1.0
    repairs: list[str] = field(default_factory=list)
    repair: RepairSummary | None = None
    shells: int = 1
    solid_index: int | None = None
    shell_note: str | None = None
    warnings: list[str] = field(default_factory=list)
    instances: list[np.ndarray | None] = field(default_factory=lambda: [None])


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
    except Exception as exc:  # trimesh raises many types for malformed files
        raise MeshError(path, f"cannot be read as {suffix[1:].upper()}: {exc}") from None
    if not isinstance(loaded, trimesh.Trimesh):
        raise MeshError(path, "empty mesh: no triangles")
    refuse_unrepairable(loaded, path)
    # STL stores every triangle's corners separately: sharing them is
    # reading the file, not repairing it
    loaded.merge_vertices()
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
            path,
            f"truncated binary STL: header announces {count} triangles ({expected} bytes), file has {len(data)} bytes",
        )


def unrepairable_defect(mesh: trimesh.Trimesh) -> str | None:
    """A defect no repair can mend (no triangles, NaN or infinite coordinates), or None."""
    if len(mesh.faces) == 0:
        return "empty mesh: no triangles"
    non_finite = int((~np.isfinite(mesh.vertices)).any(axis=1).sum())
    if non_finite:
        return f"non-finite coordinates (NaN or infinity) in {non_finite} vertices"
    return None


def refuse_unrepairable(mesh: trimesh.Trimesh, path: str | Path) -> None:
    """Refuse a mesh no repair can mend, before any repair (:class:`MeshError` naming ``path`` and the defect).

    The same refusal with repair on or off: a repair must never be the first
    code to meet such coordinates.
    """
    defect = unrepairable_defect(mesh)
    if defect is not None:
        raise MeshError(path, defect)


def mesh_defects(mesh: trimesh.Trimesh) -> list[str]:
    """Defects that stop a mesh from being a closed, oriented volume; empty list if none."""
    defect = unrepairable_defect(mesh)
    if defect is not None:
        return [defect]
    defects = []
    merged = mesh.copy()
    merged.merge_vertices()
    if not merged.is_watertight:
        _, counts = np.unique(merged.edges_sorted, axis=0, return_counts=True)
        boundary, shared = int((counts == 1).sum()), int((counts > 2).sum())
        what = (
            ", ".join(
                text
                for n, text in (
                    (boundary, f"{boundary} boundary edges"),
                    (shared, f"{shared} edges shared by more than two triangles"),
                )
                if n
            )
            or "degenerate triangles"
        )
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
    """Repair a mesh the way a slicer takes it (see :mod:`fcso.repair`).

    Merges duplicate vertices, drops degenerate and duplicated triangles,
    makes each shell's winding consistent, closes open shells' holes
    (MeshFix), turns inside-out shells outward and unites overlapping shells
    (manifold3d).

    Returns
    -------
    mesh : trimesh.Trimesh
        The repaired copy (empty if no shell encloses a volume).
    changes : list of str
        One line per kind of change made.

    Raises
    ------
    MeshError
        A repaired shell manifold3d cannot take.
    """
    shells, summary = repair_shells(mesh)
    if not shells:
        return trimesh.Trimesh(), summary.lines
    return trimesh.util.concatenate([s.mesh for s in unite_shells(shells, "mesh")]), summary.lines


def validate_mesh(mesh: trimesh.Trimesh, path: str | Path, repair: bool = False) -> tuple[trimesh.Trimesh, list[str]]:
    """Check that ``mesh`` is a closed, oriented volume; repair first if asked.

    Raises
    ------
    MeshError
        Naming ``path`` and the first defect (after repair, if it was asked for; one
        no repair can mend before it).
    """
    refuse_unrepairable(mesh, path)
    if repair:
        solids, _, summary = _repaired_solids(mesh, path)
        return trimesh.util.concatenate([s.mesh for s in solids]), summary.lines
    defects = mesh_defects(mesh)
    if defects:
        raise MeshError(path, defects[0] + " (run with --repair to try to fix it)")
    mesh = mesh.copy()
    mesh.merge_vertices()
    return mesh, []


def _repaired_solids(
    mesh: trimesh.Trimesh, path: str | Path
) -> tuple[list[Solid], list[trimesh.Trimesh], RepairSummary]:
    """The solids of a repaired mesh, its closed shells (file units), and what repair changed.

    Raises
    ------
    MeshError
        Naming ``path`` and the defect left when repair cannot make a closed volume.
    """
    shells, summary = repair_shells(mesh)
    if not shells:
        defect = (mesh_defects(mesh) or ["no closed volume"])[0]
        raise MeshError(path, f"{defect}; even after --repair no shell encloses a volume")
    solids = unite_shells(shells, path) if len(shells) > 1 else [Solid(mesh=shells[0], shells=1)]
    # by manifold3d's topology: lobes of a solid may touch along an edge without sharing it
    failed = sum(1 for s in solids if not (s.mesh.is_watertight and s.mesh.volume > 0))
    if failed:
        raise MeshError(path, f"{failed} of {len(solids)} solids not closed even after --repair")
    summary.volume_after = sum(float(s.mesh.volume) for s in solids)
    summary.solids_out = len(solids)
    return solids, shells, summary


def _geometry_key(mesh: trimesh.Trimesh) -> str:
    return hashlib.sha256(
        np.ascontiguousarray(mesh.vertices, dtype=np.float64).tobytes()
        + np.ascontiguousarray(mesh.faces, dtype=np.int64).tobytes()
    ).hexdigest()


def load_parts(
    path: str | Path,
    units: str | float = "mm",
    scale_to_mm: float | None = None,
    repair: bool = False,
    split_bodies: bool = True,
    max_uncompressed_bytes: int = MAX_3MF_UNCOMPRESSED_BYTES,
    max_repair_volume_change_percent: float | None = None,
    max_repair_deviation_mm: float | None = None,
) -> list[Part]:
    """Load every part of a mesh file, as a slicer would print it.

    Parameters
    ----------
    path : str or Path
        STL, 3MF, OBJ, PLY (or DAE) file. A 3MF gives one part per distinct
        object of its build (its own unit; ``units`` is not applied).
    units : {'mm', 'inch', 'm'} or float
        Unit of a plain mesh file's coordinates, or a factor to millimetres.
    scale_to_mm : float, optional
        Scale each mesh uniformly so its longest bounding-box side is this
        long (mm), before splitting it into solids.
    repair : bool
        Repair with :func:`fcso.repair.repair_shells` before validating.
    split_bodies : bool
        Separate solids become separate parts ``<name>#<k>`` (largest first);
        False refuses such a file.
    max_uncompressed_bytes : int
        Zip-bomb limit of a 3MF, bytes.
    max_repair_volume_change_percent, max_repair_deviation_mm : float, optional
        A repair that changes the shells' volume by more than this (%), or
        moves a corner farther than this from the file's triangles (mm), is
        refused (``[parts] repair_max_*``); None: no limit.

    Returns
    -------
    list of Part
        Overlapping or touching shells united into one solid each.

    Raises
    ------
    MeshError
        Naming the file and the defect (also several solids with
        ``split_bodies=False``).
    RepairToleranceError
        A repair beyond the limits, with its figures.
    """
    path = Path(path)
    if path.suffix.lower() == ".3mf":
        items = read_3mf_items(path, max_uncompressed_bytes)
        factor = 1.0
    else:
        items = [MeshItem(name=path.stem, mesh=read_mesh(path))]
        factor = unit_factor(units, path)
    distinct: dict[str, tuple[MeshItem, list[np.ndarray | None]]] = {}
    for item in items:
        distinct.setdefault(_geometry_key(item.mesh), (item, []))[1].append(item.transform)
    one_object = len(distinct) == 1
    parts = []
    for item, transforms in distinct.values():
        name = path.stem if one_object else item.name
        where = path if one_object or not path.suffix.lower() == ".3mf" else f"{path} (build item {item.name})"
        mesh = item.mesh
        refuse_unrepairable(mesh, where)
        summary = None
        if repair:
            solids, closed, summary = _repaired_solids(mesh, where)
            shells, shell_sum = len(closed), sum(float(s.volume) for s in closed)
        else:
            mesh, _ = validate_mesh(mesh, where)
            solids, shells = mesh_solids(mesh, where)
            shell_sum = float(mesh.volume)
        scale = factor
        if scale_to_mm is not None:
            if not scale_to_mm > 0:
                raise MeshError(path, f"scale-to length must be positive, got {scale_to_mm}")
            bounds = np.array([s.mesh.bounds for s in solids])
            scale = scale_to_mm / float((bounds[:, 1].max(axis=0) - bounds[:, 0].min(axis=0)).max())
        if summary is not None:
            _check_repair(summary, scale, where, max_repair_volume_change_percent, max_repair_deviation_mm)
        for solid in solids:
            solid.mesh.apply_scale(scale)
        if len(solids) > 1 and not split_bodies:
            raise MeshError(
                where,
                f"holds {len(solids)} separate solids (parts.split_bodies = false): split the file or allow splitting",
            )
        parts += _solid_parts(solids, name, path, where, scale, summary, shells, shell_sum, transforms)
    return parts


def _solid_parts(
    solids: list[Solid],
    name: str,
    path: Path,
    where: str | Path,
    scale: float,
    summary: RepairSummary | None,
    shells: int,
    shell_sum: float,
    transforms: list[np.ndarray | None],
) -> list[Part]:
    """The parts of one object of a file (:func:`load_parts`): one per solid, ``<name>#<k>`` when there are several;
    ``shell_sum`` the volume of its shells before scaling (mm³ in file units)."""
    parts = []
    warnings = []
    if len(solids) > 1:
        names = ", ".join(f"{name}#{k}" for k in range(1, len(solids) + 1))
        warnings.append(
            f"{where} holds {len(solids)} separate solids ({shells} shells): designed as separate parts {names}"
        )
    for k, solid in enumerate(solids, start=1):
        parts.append(
            Part(
                name=f"{name}#{k}" if len(solids) > 1 else name,
                path=str(path),
                mesh=solid.mesh,
                scale=scale,
                repairs=summary.lines if summary else [],
                repair=summary,
                shells=solid.shells,
                solid_index=k if len(solids) > 1 else None,
                shell_note=_shell_note(solid, k, len(solids), shells, shell_sum * scale**3),
                warnings=warnings,
                instances=transforms,
            )
        )
    return parts


def _check_repair(
    summary: RepairSummary,
    scale: float,
    where: str | Path,
    max_volume_change_percent: float | None,
    max_deviation_mm: float | None,
) -> None:
    """Refuse a repair beyond the limits (:class:`RepairToleranceError` with its figures); ``scale`` converts to mm."""
    change, deviation_mm = summary.volume_change_percent, summary.max_deviation * scale
    passed = []
    if max_volume_change_percent is not None and abs(change) > max_volume_change_percent:
        passed.append(f"parts.repair_max_volume_change_percent = {max_volume_change_percent:g}")
    if max_deviation_mm is not None and deviation_mm > max_deviation_mm:
        passed.append(f"parts.repair_max_deviation_mm = {max_deviation_mm:g}")
    if passed:
        raise RepairToleranceError(where, change, deviation_mm, "limits " + ", ".join(passed))


def _shell_note(solid: Solid, k: int, solids: int, shells: int, shell_sum_mm3: float) -> str | None:
    """How one part was made from a file's shells, for its report entry."""
    if shells == 1:
        return None
    volume = f"volume {solid.mesh.volume:.1f} mm³"
    if solids == 1:
        return (
            f"{shells} overlapping or touching shells united into one solid with manifold3d: "
            f"{volume}, where the shells add up to {shell_sum_mm3:.1f} mm³"
        )
    made = (
        f"{solid.shells} of its {shells} shells united with manifold3d"
        if solid.shells > 1
        else f"1 of its {shells} shells"
    )
    return f"solid {k} of {solids} in the file (largest first), {made}; {volume}"


def load_part(
    path: str | Path,
    units: str | float = "mm",
    scale_to_mm: float | None = None,
    repair: bool = False,
    name: str | None = None,
) -> Part:
    """Load a file that holds exactly one part (see :func:`load_parts`).

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
        Overlapping or touching shells united into one solid.

    Raises
    ------
    MeshError
        Naming the file and the defect, also when the file holds several
        separate solids or 3MF objects.
    """
    parts = load_parts(path, units=units, scale_to_mm=scale_to_mm, repair=repair)
    if len(parts) > 1:
        raise MeshError(
            path, f"holds {len(parts)} parts (separate solids or 3MF objects): load it with fcso.load_parts"
        )
    part = parts[0]
    if name is not None:
        part.name = name
    return part


def units_hint(part: Part, units: str | float, scale_to_mm: float | None) -> str | None:
    """A hint naming ``--units`` for a part read in millimetres whose size suggests another unit, or None.

    Under 12 mm a part may have been drawn in inches (a 5-inch part read as 5 mm), under 1 mm in metres too (a
    20 mm part is 0.79 inch, 0.02 m), under 0.05 mm in metres only: shown when a design of it fails, where the
    size is the likely cause.
    """
    if scale_to_mm is not None or unit_factor(units) != 1.0:
        return None
    longest = float(max(part.mesh.extents))
    choices = []
    if 0.05 <= longest < 12.0:
        choices.append("in inches, load it with --units inch (x25.4)")
    if longest < 1.0:
        choices.append("in metres, with --units m (x1000)")
    if not choices:
        return None
    return f"{part.path}: its longest side is {longest:.3g} mm read in millimetres; if the file is " + "; if ".join(
        choices
    )
