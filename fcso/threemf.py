"""Reading 3MF files: their build items, each with its transform, in millimetres, and the zip-bomb check made before."""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from .errors import MeshError

#: Refuse a 3MF whose entries would inflate beyond this many bytes in memory.
MAX_3MF_UNCOMPRESSED_BYTES = 1 << 30
#: Refuse a 3MF entry that inflates more than this many times (zip bomb).
MAX_3MF_COMPRESSION_RATIO = 1000.0
#: Refuse a 3MF archive with more entries than this.
MAX_3MF_ENTRIES = 10_000

# 3MF's unit names and their length in millimetres
_3MF_UNIT_MM = {
    "micron": 1e-3,
    "millimeter": 1.0,
    "centimeter": 10.0,
    "inch": 25.4,
    "foot": 304.8,
    "meter": 1000.0,
}


@dataclass
class MeshItem:
    """One mesh of a file as it was read: a plain mesh file's mesh or a 3MF build item.

    Attributes
    ----------
    name : str
        The file stem, or ``<stem>/<item>`` for a 3MF build item.
    mesh : trimesh.Trimesh
        Geometry in its own frame; a 3MF item is already in mm.
    transform : (4, 4) float or None
        3MF item transform (mesh frame to build frame, mm); None for a plain mesh file.
    """

    name: str
    mesh: trimesh.Trimesh
    transform: np.ndarray | None = None


def check_zip_archive(
    path: str | Path,
    max_uncompressed_bytes: int = MAX_3MF_UNCOMPRESSED_BYTES,
    max_ratio: float = MAX_3MF_COMPRESSION_RATIO,
) -> None:
    """Refuse a zip (3MF) archive that would inflate too much before reading it.

    Python's zipfile stops each entry at its declared size, so checking the
    declared sizes bounds the memory a reader can take.

    Raises
    ------
    MeshError
        Not a zip archive, too many entries, total inflated size above
        ``max_uncompressed_bytes`` or an entry inflating more than ``max_ratio``
        times.
    """
    try:
        with zipfile.ZipFile(path) as archive:
            entries = archive.infolist()
    except (zipfile.BadZipFile, OSError) as exc:
        raise MeshError(path, f"not a readable 3MF (zip) archive: {exc}") from None
    if len(entries) > MAX_3MF_ENTRIES:
        raise MeshError(path, f"3MF archive holds {len(entries)} entries (limit {MAX_3MF_ENTRIES})")
    total = sum(entry.file_size for entry in entries)
    if total > max_uncompressed_bytes:
        raise MeshError(path, f"3MF inflates to {total} bytes (limit {max_uncompressed_bytes}): refused as a zip bomb")
    for entry in entries:
        ratio = entry.file_size / max(entry.compress_size, 1)
        if ratio > max_ratio:
            raise MeshError(
                path,
                f"3MF entry {entry.filename!r} inflates {ratio:.0f} times (limit {max_ratio:.0f}): "
                "refused as a zip bomb",
            )


def read_3mf_items(path: str | Path, max_uncompressed_bytes: int = MAX_3MF_UNCOMPRESSED_BYTES) -> list[MeshItem]:
    """The build items of a 3MF file, each with its transform, in millimetres.

    Every mesh instance of the build becomes an item (trimesh flattens
    components, so a build item made of several bodies gives one item per
    body), named ``<stem>/<node>``.

    Raises
    ------
    MeshError
        A zip bomb, an unreadable file or a build without items.
    """
    path = Path(path)
    check_zip_archive(path, max_uncompressed_bytes)
    try:
        scene = trimesh.load(str(path), file_type="3mf", force="scene", process=False)
    except Exception as exc:  # trimesh raises many types for malformed files
        raise MeshError(path, f"cannot be read as 3MF: {exc}") from None
    # trimesh keeps 3MF coordinates in the file's unit (it reports the unit name)
    unit = str(scene.units or "millimeter").lower().rstrip("s")
    if unit not in _3MF_UNIT_MM:
        raise MeshError(path, f"unknown 3MF unit {scene.units!r}")
    to_mm = _3MF_UNIT_MM[unit]
    items = []
    for node in sorted(scene.graph.nodes_geometry):
        matrix, geometry_name = scene.graph[node]
        mesh = scene.geometry[geometry_name]
        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
            continue
        mesh = mesh.copy()
        mesh.apply_scale(to_mm)
        transform = np.array(matrix, dtype=float)
        transform[:3, 3] *= to_mm
        items.append(MeshItem(name=f"{path.stem}/{node}", mesh=mesh, transform=transform))
    if not items:
        raise MeshError(path, "3MF build holds no mesh items")
    return items
