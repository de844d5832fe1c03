"""A job's build: its items (parts and fingers) with their placements, read from
a 3MF or from loose meshes, and written back as ``build.3mf``.

Lengths are millimetres. A transform is a 4x4 homogeneous matrix taking an
item's mesh frame to the build-volume frame; ``None`` means not placed yet.
"""

from __future__ import annotations

import io
import uuid
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import trimesh
from lxml import etree

from fcso.parts import read_mesh, unit_factor
from fcso.threemf import MAX_3MF_UNCOMPRESSED_BYTES, read_3mf_items

from .models import parse_transform

_CORE_NS = "http://schemas.microsoft.com/3dmanufacturing/core/2015/02"
_PRODUCTION_NS = "http://schemas.microsoft.com/3dmanufacturing/production/2015/06"
#: Namespace of fcsod's own metadata (``fcso:job_id``, ``fcso:finger_set``) in ``build.3mf``.
FCSO_3MF_NS = "urn:fcsod:3mf:2026"
#: Namespace of the deterministic UUIDs of ``build.3mf`` (uuid5 of job id and item).
_UUID_NAMESPACE = uuid.UUID("5b0a7c52-4f6e-5d1c-9a57-2f1b0d3c6e11")
_CONTENT_TYPES = (
    b'<?xml version="1.0" encoding="UTF-8"?>\n'
    b'<Types xmlns="http://schemas.openxmlformats.org/package/2006/content-types">'
    b'<Default Extension="rels" ContentType="application/vnd.openxmlformats-package.relationships+xml"/>'
    b'<Default Extension="model" ContentType="application/vnd.ms-package.3dmanufacturing-3dmodel+xml"/>'
    b"</Types>"
)
_RELS = (
    b'<?xml version="1.0" encoding="UTF-8"?>\n'
    b'<Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships">'
    b'<Relationship Target="/3D/3dmodel.model" Id="rel0" '
    b'Type="http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"/>'
    b"</Relationships>"
)


@dataclass
class BuildItem:
    """One object of a build.

    Attributes
    ----------
    name : str
        Unique within the build; the item's name in ``build.3mf``.
    mesh : trimesh.Trimesh
        Geometry in its own frame, mm.
    transform : (4, 4) float or None
        Mesh frame to build-volume frame; ``None`` when not placed.
    kind : {'part', 'finger'}
        A job part or a finger copy.
    part_number : str or None
        Part number of the item's object in ``build.3mf``: the part file's
        stem; ``None``: the name (finger objects are ``fcso-finger-<set>``).
    finger_set : int or None
        A finger copy's set when the job has several; ``None``: the export's ``finger_set``.
    """

    name: str
    mesh: trimesh.Trimesh
    transform: np.ndarray | None = None
    kind: Literal["part", "finger"] = "part"
    part_number: str | None = None
    finger_set: int | None = None

    def placed_mesh(self) -> trimesh.Trimesh:
        """The mesh moved by its transform (a copy); the item must be placed."""
        if self.transform is None:
            raise ValueError(f"build item {self.name!r} has no transform")
        return self.mesh.copy().apply_transform(self.transform)


@dataclass
class Build:
    """The items of one print job.

    Attributes
    ----------
    items : list of BuildItem
        Parts (and, after placement, fingers).
    source : str
        Where the build was read from, for messages.
    """

    items: list[BuildItem] = field(default_factory=list)
    source: str = ""

    @property
    def placed(self) -> bool:
        """True when every item has a transform (a placed build)."""
        return bool(self.items) and all(item.transform is not None for item in self.items)


def read_build_3mf(path: str | Path, max_uncompressed_bytes: int = MAX_3MF_UNCOMPRESSED_BYTES) -> list[BuildItem]:
    """The build items of a 3MF file, placed, in millimetres (:func:`fcso.read_3mf_items`).

    Items are named after their build items (without the file stem).

    Raises
    ------
    MeshError
        A zip bomb, an unreadable file or a build without items.
    """
    return [
        BuildItem(name=item.name.split("/", 1)[1], mesh=item.mesh, transform=item.transform)
        for item in read_3mf_items(path, max_uncompressed_bytes)
    ]


def read_build(
    paths: Sequence[str | Path],
    transforms: Mapping[str, object] | None = None,
    units: Mapping[str, str | float] | None = None,
    max_uncompressed_bytes: int = MAX_3MF_UNCOMPRESSED_BYTES,
) -> Build:
    """Read a job's build from its mesh files.

    Parameters
    ----------
    paths : sequence of path
        The job's part files. A ``.3mf`` gives its build items, placed; any
        other mesh file gives one part.
    transforms : mapping, optional
        File name (or stem) to the manifest's 4x4 transform of that loose
        part (16 numbers row-major, or 4 rows), mm, applied after unit
        scaling. Loose parts without one are unplaced.
    units : mapping, optional
        File name (or stem) to ``'mm'``, ``'inch'``, ``'m'`` or a factor for
        loose parts; default mm.
    max_uncompressed_bytes : int
        Zip-bomb limit of each 3MF.

    Returns
    -------
    Build
        Items named after their files (3MF items after their build items),
        made unique.

    Raises
    ------
    MeshError
        An unreadable file or transform.
    """
    transforms = transforms or {}
    units = units or {}
    items: list[BuildItem] = []
    for path in map(Path, paths):
        if path.suffix.lower() == ".3mf":
            for item in read_build_3mf(path, max_uncompressed_bytes):
                item.name = f"{path.stem}/{item.name}"
                item.part_number = path.stem
                items.append(item)
            continue
        mesh = read_mesh(path)
        mesh.apply_scale(unit_factor(_by_file(units, path, "mm"), path))
        value = _by_file(transforms, path, None)
        transform = None if value is None else parse_transform(value, f"{path.name}: transform")
        items.append(BuildItem(name=path.stem, mesh=mesh, transform=transform, part_number=path.stem))
    make_names_unique(items)
    return Build(items=items, source=", ".join(str(p) for p in paths))


def _by_file(mapping: Mapping[str, object], path: Path, default):
    """A manifest value keyed by file name or by stem."""
    return mapping.get(path.name, mapping.get(path.stem, default))


def make_names_unique(items: Sequence[BuildItem]) -> None:
    """Suffix repeated item names with ``_2``, ``_3``... (in place)."""
    seen: dict[str, int] = {}
    for item in items:
        count = seen.get(item.name, 0) + 1
        seen[item.name] = count
        if count > 1:
            item.name = f"{item.name}_{count}"


def export_build_3mf(
    items: Sequence[BuildItem],
    job_id: str = "",
    application: str = "fcsod",
    creation_date: str = "1980-01-01",
    finger_set: int = 1,
) -> bytes:
    """``build.3mf`` bytes: a production 3MF with one object per distinct mesh and one build item per item.

    Items sharing one mesh object (the finger copies) share one 3MF object.
    Objects are named and numbered after their part (the part file's stem,
    or ``fcso-finger-<set>``); each item's part number is its unique name in
    the build (``cube``, ``cube_2``, finger copies ``fcso-finger-<set>-<copy>``),
    which slicers and trimesh show as the item's name. The build, every item and every
    object carry a Production-extension ``p:UUID`` derived from the job id
    and the name (uuid5), so the same job gives the same UUIDs and bytes.
    The model's metadata holds ``Title`` (the job id), ``Application`` and
    ``CreationDate``; finger items carry ``fcso:job_id`` and
    ``fcso:finger_set``. Meshes are written with outward normals (a mesh of
    negative volume is flipped).

    Parameters
    ----------
    items : sequence of BuildItem
        Placed items (every transform set), mm.
    job_id : str
        The job, for the title, the UUIDs and the finger metadata.
    application : str
        ``Application`` metadata (``fcsod <version>``).
    creation_date : str
        ``CreationDate`` metadata, ISO 8601 (UTC date and time).
    finger_set : int
        Number of the finger set (the ``<set>`` of the finger part numbers) of finger items without their own.

    Returns
    -------
    bytes
        A 3MF (core and production specifications, unit millimeter).
    """
    p_uuid = f"{{{_PRODUCTION_NS}}}UUID"
    object_ids: dict[int, int] = {}
    model = etree.Element(
        f"{{{_CORE_NS}}}model", nsmap={None: _CORE_NS, "p": _PRODUCTION_NS, "fcso": FCSO_3MF_NS}, unit="millimeter"
    )
    model.set("{http://www.w3.org/XML/1998/namespace}lang", "en-US")
    for name, value in (("Title", job_id), ("Application", application), ("CreationDate", creation_date)):
        etree.SubElement(model, f"{{{_CORE_NS}}}metadata", name=name).text = value
    resources = etree.SubElement(model, f"{{{_CORE_NS}}}resources")
    build = etree.SubElement(model, f"{{{_CORE_NS}}}build", {p_uuid: _uuid(job_id, "build")})
    for item in items:
        if item.transform is None:
            raise ValueError(f"build item {item.name!r} has no transform")
        key = id(item.mesh)
        if key not in object_ids:
            object_ids[key] = len(object_ids) + 1
            object_part_number = (
                f"fcso-finger-{item.finger_set or finger_set}"
                if item.kind == "finger"
                else item.part_number or item.name
            )
            _add_mesh_object(
                resources, object_ids[key], object_part_number, item.mesh, _uuid(job_id, f"object/{object_ids[key]}")
            )
        element = etree.SubElement(
            build,
            f"{{{_CORE_NS}}}item",
            {
                "objectid": str(object_ids[key]),
                "transform": _transform_attribute(item.transform),
                "partnumber": item.name,
                p_uuid: _uuid(job_id, f"item/{item.name}"),
            },
        )
        if item.kind == "finger":
            group = etree.SubElement(element, f"{{{_CORE_NS}}}metadatagroup")
            for name, value in (("fcso:job_id", job_id), ("fcso:finger_set", str(item.finger_set or finger_set))):
                etree.SubElement(group, f"{{{_CORE_NS}}}metadata", name=name, preserve="1").text = value
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for name, data in (
            ("[Content_Types].xml", _CONTENT_TYPES),
            ("_rels/.rels", _RELS),
            ("3D/3dmodel.model", etree.tostring(model, xml_declaration=True, encoding="UTF-8")),
        ):
            # a fixed timestamp keeps the archive bytes reproducible
            archive.writestr(zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0)), data, zipfile.ZIP_DEFLATED)
    return buffer.getvalue()


def _uuid(job_id: str, name: str) -> str:
    """A UUID fixed by the job and the element's name (uuid5), as 3MF writes it."""
    return str(uuid.uuid5(_UUID_NAMESPACE, f"{job_id}/{name}"))


def write_build_3mf(items: Sequence[BuildItem], path: str | Path) -> Path:
    """Write :func:`export_build_3mf` to ``path`` (the caller renames it into place)."""
    path = Path(path)
    path.write_bytes(export_build_3mf(items))
    return path


def _add_mesh_object(resources, object_id: int, part_number: str, mesh: trimesh.Trimesh, object_uuid: str) -> None:
    """Append a 3MF ``object`` named and numbered ``part_number`` holding ``mesh``, faces wound outward, to
    ``resources``.
    """
    obj = etree.SubElement(
        resources,
        f"{{{_CORE_NS}}}object",
        {
            "id": str(object_id),
            "type": "model",
            "name": part_number,
            "partnumber": part_number,
            f"{{{_PRODUCTION_NS}}}UUID": object_uuid,
        },
    )
    mesh_element = etree.SubElement(obj, f"{{{_CORE_NS}}}mesh")
    vertices = etree.SubElement(mesh_element, f"{{{_CORE_NS}}}vertices")
    for x, y, z in np.asarray(mesh.vertices, dtype=float).tolist():
        etree.SubElement(vertices, f"{{{_CORE_NS}}}vertex", x=repr(x), y=repr(y), z=repr(z))
    triangles = etree.SubElement(mesh_element, f"{{{_CORE_NS}}}triangles")
    faces = np.asarray(mesh.faces, dtype=np.int64)
    # a closed mesh of negative signed volume is wound inward: 3MF wants outward normals
    if mesh.is_watertight and mesh.volume < 0:
        faces = faces[:, ::-1]
    for v1, v2, v3 in faces.tolist():
        etree.SubElement(triangles, f"{{{_CORE_NS}}}triangle", v1=str(v1), v2=str(v2), v3=str(v3))


def _transform_attribute(transform: np.ndarray) -> str:
    """The 3MF ``transform`` attribute of a 4x4 transform.

    3MF multiplies row vectors, so it stores the transposed 3x3 block row by
    row (m00 m01 m02 m10 ... m22) and then the translation; ``repr`` keeps
    every float exact through a reload.
    """
    matrix = np.asarray(transform, dtype=float)
    values = matrix[:3, :3].T.reshape(-1).tolist() + matrix[:3, 3].tolist()
    return " ".join(repr(value) for value in values)
