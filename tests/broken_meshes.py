"""Broken versions of real closed meshes, the way exporters break them (tests and benchmarks.bench_repair)."""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path

import manifold3d
import numpy as np
import trimesh

#: The ways :func:`break_mesh` breaks a mesh.
KINDS = ("holes", "overlap", "flipped", "duplicated", "all")

#: Where ``overlap`` puts the second body, as a fraction of the mesh's extents.
OVERLAP_SHIFT = np.array([0.3, 0.2, 0.1])


def break_mesh(mesh: trimesh.Trimesh, kind: str, seed: int = 23) -> trimesh.Trimesh:
    """A broken copy of a closed mesh.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Closed mesh with shared vertices.
    kind : str
        ``holes``: three holes, each a triangle and its nearly coplanar
        neighbours deleted (an exporter losing part of one CAD face);
        ``overlap``: the mesh and a copy moved by ``OVERLAP_SHIFT`` of its
        extents, overlapping, each with its own vertices and one such hole;
        ``flipped``: 5 % of the triangles turned over; ``duplicated``: 5 % of
        the triangles twice; ``all``: overlap, then 5 % flipped and 5 % duplicated.
    seed : int
        Seed of the random choices.
    """
    rng = np.random.default_rng(seed)
    if kind == "holes":
        return _holes(mesh, 3, rng)
    if kind == "flipped":
        return _flip(mesh, rng)
    if kind == "duplicated":
        return _duplicate(mesh, rng)
    if kind not in ("overlap", "all"):
        raise ValueError(f"unknown kind {kind!r} (use {', '.join(KINDS)})")
    moved = mesh.copy()
    moved.apply_translation(OVERLAP_SHIFT * mesh.extents)
    overlap = trimesh.util.concatenate([_holes(mesh, 1, rng), _holes(moved, 1, rng)])
    return overlap if kind == "overlap" else _duplicate(_flip(overlap, rng), rng)


def intact_mesh(mesh: trimesh.Trimesh, kind: str) -> trimesh.Trimesh:
    """The closed shells ``break_mesh(mesh, kind)`` was made from (for ``overlap``: both bodies)."""
    if kind not in ("overlap", "all"):
        return mesh
    moved = mesh.copy()
    moved.apply_translation(OVERLAP_SHIFT * mesh.extents)
    return trimesh.util.concatenate([mesh, moved])


def intact_volume(mesh: trimesh.Trimesh, kind: str) -> float:
    """Volume the repair of ``break_mesh(mesh, kind)`` should give, from the intact mesh (file units³)."""
    if kind not in ("overlap", "all"):
        return float(mesh.volume)
    body = manifold3d.Manifold(
        manifold3d.Mesh(
            vert_properties=np.asarray(mesh.vertices, np.float32), tri_verts=np.asarray(mesh.faces, np.uint32)
        )
    )
    moved = body.translate(tuple(float(x) for x in OVERLAP_SHIFT * mesh.extents))
    return float((body + moved).volume())


def _holes(mesh: trimesh.Trimesh, count: int, rng: np.random.Generator) -> trimesh.Trimesh:
    adjacency = mesh.face_adjacency
    normals = mesh.face_normals
    dropped = set()
    for face in rng.choice(len(mesh.faces), count, replace=False):
        neighbours = adjacency[(adjacency == face).any(axis=1)].ravel()
        dropped.update(int(x) for x in neighbours if normals[x] @ normals[face] > 0.95)
        dropped.add(int(face))
    keep = np.ones(len(mesh.faces), bool)
    keep[list(dropped)] = False
    return trimesh.Trimesh(mesh.vertices, mesh.faces[keep], process=False)


def _flip(mesh: trimesh.Trimesh, rng: np.random.Generator) -> trimesh.Trimesh:
    faces = mesh.faces.copy()
    chosen = rng.choice(len(faces), max(1, len(faces) // 20), replace=False)
    faces[chosen] = faces[chosen][:, ::-1]
    return trimesh.Trimesh(mesh.vertices, faces, process=False)


def _duplicate(mesh: trimesh.Trimesh, rng: np.random.Generator) -> trimesh.Trimesh:
    chosen = rng.choice(len(mesh.faces), max(1, len(mesh.faces) // 20), replace=False)
    return trimesh.Trimesh(mesh.vertices, np.vstack([mesh.faces, mesh.faces[chosen]]), process=False)


def sheet_stl(path: Path) -> bytes:
    """The upward faces of the real mesh at ``path`` as binary STL: a surface that encloses no volume, which no
    repair can make a part.
    """
    mesh = trimesh.load(path, force="mesh")
    return trimesh.Trimesh(mesh.vertices, mesh.faces[mesh.face_normals[:, 2] > 0.99]).export(file_type="stl")


@dataclass(frozen=True)
class BadInput:
    """A part file every loader refuses, repair on or off, and the words its one-line refusal holds.

    Attributes
    ----------
    file : str
        File name in the folder :func:`write_bad_inputs` wrote to.
    defect : str
        Words of the refusal without repair.
    defect_with_repair : str
        Words of the refusal with repair on (the same defect: repair cannot mend it).
    """

    file: str
    defect: str
    defect_with_repair: str


#: Files the loader refuses with repair on as without: repair mends open, flipped, overlapping shells, never these.
BAD_INPUTS = (
    BadInput("truncated.stl", "truncated binary STL", "truncated binary STL"),
    BadInput("nan.stl", "non-finite coordinates", "non-finite coordinates"),
    BadInput("nan_everywhere.stl", "non-finite coordinates", "non-finite coordinates"),
    BadInput("infinite.ply", "non-finite coordinates", "non-finite coordinates"),
    BadInput("empty.stl", "empty mesh", "empty mesh"),
    BadInput("garbage.ply", "cannot be read as PLY", "cannot be read as PLY"),
    BadInput("notes.txt", "unsupported file type", "unsupported file type"),
    BadInput("zip_bomb.3mf", "zip bomb", "zip bomb"),
    BadInput("sheet.stl", "not watertight", "even after --repair"),
)


def write_bad_inputs(folder: Path, source: Path) -> None:
    """Write every file of :data:`BAD_INPUTS` to ``folder``, made from the real closed mesh at ``source``."""
    mesh = trimesh.load(source, force="mesh")
    (folder / "truncated.stl").write_bytes(mesh.export(file_type="stl")[:3000])
    one_corner = mesh.vertices.copy()
    one_corner[3] = np.nan
    trimesh.Trimesh(one_corner, mesh.faces, process=False).export(folder / "nan.stl")
    nowhere = np.full_like(mesh.vertices, np.nan)
    trimesh.Trimesh(nowhere, mesh.faces, process=False).export(folder / "nan_everywhere.stl")
    far = mesh.vertices.copy()
    far[7] = np.inf
    trimesh.Trimesh(far, mesh.faces, process=False).export(folder / "infinite.ply")
    (folder / "empty.stl").write_bytes(b"\0" * 80 + (0).to_bytes(4, "little"))
    header = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\n"
    (folder / "garbage.ply").write_bytes(header + bytes(range(256)))
    (folder / "notes.txt").write_text("not a mesh\n")
    with zipfile.ZipFile(folder / "zip_bomb.3mf", "w", compression=zipfile.ZIP_BZIP2) as archive:
        archive.writestr("3D/3dmodel.model", b"\0" * (64 << 20))
    (folder / "sheet.stl").write_bytes(sheet_stl(source))


def two_solids_with_degenerate_triangles(first: trimesh.Trimesh, second: trimesh.Trimesh) -> trimesh.Trimesh:
    """Two real closed meshes side by side, 10 mm apart, with the zero-area triangles exporters leave.

    On ``first``: an edge split at its midpoint by a T-junction, closed by the zero-area triangle over it
    (watertight with it, open without it). On ``second``: triangles with a repeated corner.
    """
    second = second.copy()
    second.apply_translation([first.bounds[1, 0] - second.bounds[0, 0] + 10.0, 0.0, 0.0])
    vertices = np.vstack([first.vertices, second.vertices])
    faces = np.vstack([first.faces, second.faces + len(first.vertices)])
    i, j, k = faces[0]
    midpoint = len(vertices)
    vertices = np.vstack([vertices, (vertices[i] + vertices[j]) / 2])
    faces[0] = [i, midpoint, k]
    collapsed = second.faces[:2, :2] + len(first.vertices)
    degenerate = [[midpoint, j, k], [i, j, midpoint], *([a, a, b] for a, b in collapsed)]
    return trimesh.Trimesh(vertices, np.vstack([faces, degenerate]), process=False)
