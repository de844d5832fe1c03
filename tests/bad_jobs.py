"""Bad job folders as users and attackers drop them, each with the words its refusal must hold (the daemon's corpus:
tests/fcsod/test_bad_input.py, and the shipped-daemon e2e test)."""

from __future__ import annotations

import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from tests.broken_meshes import sheet_stl

DATA = Path(__file__).resolve().parent / "data"
CUBE = DATA / "20mm-xyz-cube.stl"


@dataclass(frozen=True)
class BadJob:
    """A bad job folder and its expected refusal.

    Attributes
    ----------
    name : str
        The job folder's name.
    write : callable
        Writes the folder's files into the given (existing) folder.
    file : str
        The file the refusal must name.
    words : tuple of str
        Further words the refusal must hold, whether the daemon repairs parts or not.
    mesh : bool
        The defect is in a mesh file: ``fcso design FILE`` refuses it too.
    """

    name: str
    write: Callable[[Path], None]
    file: str
    words: tuple[str, ...]
    mesh: bool = False


def _truncated(folder: Path) -> None:
    (folder / "cut.stl").write_bytes((DATA / "solar_tracker.stl").read_bytes()[:10_000])


def _nan(folder: Path) -> None:
    mesh = trimesh.load(CUBE)
    vertices = mesh.vertices.copy()
    vertices[3] = np.nan
    trimesh.Trimesh(vertices, mesh.faces, process=False).export(folder / "nan.stl")


def _open(folder: Path) -> None:
    (folder / "top_face.stl").write_bytes(sheet_stl(CUBE))


def _empty(folder: Path) -> None:
    (folder / "empty.stl").write_bytes(b"\0" * 80 + (0).to_bytes(4, "little"))


def _symlink(folder: Path) -> None:
    outside = folder.parent / f"{folder.name}-outside.stl"
    outside.write_bytes(CUBE.read_bytes())
    (folder / "link.stl").symlink_to(outside)


def _traversal(folder: Path) -> None:
    (folder / "job.toml").write_text('[[parts]]\nfile = "../secret.stl"\n', encoding="utf-8")
    (folder / "cube.stl").write_bytes(CUBE.read_bytes())


def _zip_bomb(folder: Path) -> None:
    with zipfile.ZipFile(folder / "bomb.3mf", "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("3D/3dmodel.model", b"\0" * 20_000_000)


def _unknown_key(folder: Path) -> None:
    (folder / "job.toml").write_text("[gripper]\nmax_opening_mm = 60\nmax_openign_mm = 70\n", encoding="utf-8")
    (folder / "cube.stl").write_bytes(CUBE.read_bytes())


#: Every bad job: the mesh defects first (the CLI refuses those files too), then the folder's and the manifest's.
BAD_JOBS = [
    BadJob("truncated", _truncated, "cut.stl", ("truncated",), mesh=True),
    BadJob("nan", _nan, "nan.stl", ("non-finite",), mesh=True),
    BadJob("open-mesh", _open, "top_face.stl", ("open mesh",), mesh=True),
    BadJob("empty", _empty, "empty.stl", ("empty mesh",), mesh=True),
    BadJob("symlink", _symlink, "link.stl", ("symlink pointing outside the job folder",)),
    BadJob("traversal", _traversal, "job.toml", ("../secret.stl", "path leaves the job folder")),
    BadJob("zip-bomb", _zip_bomb, "bomb.3mf", ("zip bomb",)),
    BadJob("unknown-key", _unknown_key, "job.toml", ("gripper.max_openign_mm: unknown key",)),
]


def write_bad_job(folder: Path, job: BadJob) -> None:
    """Create ``folder`` holding ``job``'s files."""
    folder.mkdir(parents=True)
    job.write(folder)
