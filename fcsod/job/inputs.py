"""Job folders: which files are a job's inputs, when the job is ready, its identity, and the checks on its inputs.

Everything here reads the job folder and never writes to it.
"""

from __future__ import annotations

import hashlib
import os
import re
import tomllib
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fcso.config import DesignConfig
from fcso.errors import ConfigError, MeshError
from fcso.parts import MESH_SUFFIXES

from ..bus.messages import InputFile
from ..config import MANIFEST_NAME, JobManifest, LimitsConfig, PartEntry, parse_manifest
from ..plate.models import BuildConfig
from ..storage import file_sha256

#: (relative path, size in bytes, mtime in ns); size -1 for a missing file.
FileStat = tuple[str, int, int]


def list_files(folder: Path) -> list[str]:
    """Every file (and symlink) below ``folder`` as sorted POSIX paths relative to it; symlinks are not followed."""
    found = []
    for directory, subdirs, files in os.walk(folder, followlinks=False):
        base = Path(directory)
        # a symlinked folder is listed but not entered: it is checked like a file
        names = files + [d for d in subdirs if (base / d).is_symlink()]
        found.extend((base / name).relative_to(folder).as_posix() for name in names)
    return sorted(found)


def is_mesh(relative: str) -> bool:
    """Whether a file name has an ending fcso reads as a part."""
    return Path(relative).suffix.lower() in MESH_SUFFIXES


def inside(folder: Path, relative: str) -> Path | None:
    """The file ``relative`` names in ``folder``, or None when it leaves the folder (absolute, ``..`` or a symlink
    out).
    """
    if Path(relative).is_absolute():
        return None
    resolved_folder = folder.resolve()
    target = (folder / relative).resolve()
    if target != resolved_folder and resolved_folder not in target.parents:
        return None
    return folder / relative


def manifest_files(folder: Path) -> list[str] | None:
    """Files a manifest names, read leniently for readiness; None without a readable manifest.

    A manifest that does not parse (yet) names nothing; an empty list means
    the manifest names no parts (every mesh file is then a part).
    """
    try:
        data = tomllib.loads((folder / MANIFEST_NAME).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return None
    parts = data.get("parts")
    if not isinstance(parts, list):
        return []
    return [p["file"] for p in parts if isinstance(p, dict) and isinstance(p.get("file"), str)]


@dataclass(frozen=True)
class FolderInputs:
    """The files that make a job, and those a manifest names that are not there (yet)."""

    files: tuple[str, ...]
    missing: tuple[str, ...]


def job_inputs(folder: Path) -> FolderInputs:
    """A job's input files.

    With a readable manifest: the manifest and the files it names (every
    mesh file when it names none). Otherwise: every file of the folder.
    """
    everything = list_files(folder)
    if MANIFEST_NAME not in everything:
        return FolderInputs(tuple(everything), ())
    named = manifest_files(folder)
    if named is None:
        return FolderInputs(tuple(everything), ())
    if not named:
        return FolderInputs(tuple([MANIFEST_NAME] + [f for f in everything if is_mesh(f)]), ())
    present, missing = [MANIFEST_NAME], []
    for name in dict.fromkeys(named):
        path = inside(folder, name)
        # a name that leaves the folder is an input too: the job must fail on it
        if path is None or path.is_file() or path.is_symlink():
            present.append(name)
        else:
            missing.append(name)
    return FolderInputs(tuple(present), tuple(missing))


def stat_inputs(folder: Path, inputs: FolderInputs) -> tuple[FileStat, ...]:
    """Size and mtime of each input (the readiness signature); a vanished file has size -1."""
    stats = []
    for name in inputs.files + inputs.missing:
        path = inside(folder, name)
        try:
            info = os.lstat(path) if path is not None else None
        except OSError:
            info = None
        stats.append((name, info.st_size, info.st_mtime_ns) if info else (name, -1, 0))
    return tuple(stats)


def slug(name: str) -> str:
    """A folder name as a key-expression-safe chunk: lower case letters, digits, ``-`` and ``_``, at most 48
    characters.
    """
    text = re.sub(r"[^a-z0-9_-]+", "-", name.lower()).strip("-_")
    return text[:48] or "job"


def hash_inputs(folder: Path, inputs: FolderInputs, max_file_bytes: int) -> list[InputFile]:
    """Content hash of every input file.

    A name that leaves the folder is hashed as its text, and a file beyond
    ``max_file_bytes`` by its size and mtime: neither is read (the job fails on them).
    """
    hashed = []
    for name in inputs.files:
        path = inside(folder, name)
        if path is None or not path.is_file():
            marker = f"unreadable:{name}".encode()
            hashed.append(InputFile(path=name, size_bytes=0, sha256=hashlib.sha256(marker).hexdigest()))
            continue
        info = path.stat()
        if info.st_size > max_file_bytes:
            marker = f"oversize:{info.st_size}:{info.st_mtime_ns}".encode()
            hashed.append(InputFile(path=name, size_bytes=info.st_size, sha256=hashlib.sha256(marker).hexdigest()))
        else:
            hashed.append(InputFile(path=name, size_bytes=info.st_size, sha256=file_sha256(path)))
    return hashed


def job_id(folder_name: str, hashed: list[InputFile]) -> str:
    """``<folder-slug>-<12 hex>``: the hex is SHA-256 over the sorted (relative path, content hash) pairs."""
    digest = hashlib.sha256()
    for item in sorted(hashed, key=lambda f: f.path):
        digest.update(f"{item.path}\0{item.sha256}\n".encode())
    return f"{slug(folder_name)}-{digest.hexdigest()[:12]}"


@dataclass
class PartInput:
    """A part file that passed the checks, with how to load it."""

    entry: PartEntry
    path: Path


def read_manifest(
    folder: Path, defaults: DesignConfig, limits: LimitsConfig, build_defaults: BuildConfig | None = None
) -> tuple[JobManifest, str | None]:
    """The job's manifest and its text; an empty manifest (every mesh, mm) without ``job.toml``.

    ``defaults`` and ``build_defaults`` are the daemon's fcso and ``[build]``
    settings the manifest's sections override key by key.

    Raises
    ------
    ConfigError
        Naming ``job.toml`` and the key at fault.
    """
    path = folder / MANIFEST_NAME
    if not path.exists() and not path.is_symlink():
        return JobManifest(), None
    if inside(folder, MANIFEST_NAME) is None:
        raise ConfigError(path, "symlink pointing outside the job folder")
    if path.stat().st_size > limits.max_file_bytes:
        raise ConfigError(
            path, f"{path.stat().st_size} bytes, more than limits.max_file_bytes ({limits.max_file_bytes})"
        )
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(path, f"cannot read: {exc}") from None
    return parse_manifest(text, path, defaults, build_defaults), text


def check_parts(folder: Path, manifest: JobManifest, limits: LimitsConfig) -> list[PartInput]:
    """Resolve and check the job's part files before any mesh is parsed.

    Checks: paths stay inside the folder (no ``..``, no absolute path, no
    symlink out), files exist and have a mesh ending, size limits, the
    triangle count a binary STL announces, and 3MF (zip) entries against
    zip bombs.

    Raises
    ------
    ConfigError
        A manifest entry that leaves the folder or names a missing file.
    MeshError
        A part file beyond a limit or not a mesh, naming the file.
    """
    manifest_path = folder / MANIFEST_NAME
    entries = manifest.parts or [PartEntry(file=name) for name in list_files(folder) if is_mesh(name)]
    if not entries:
        raise MeshError(folder, f"no part: no mesh file ({', '.join(MESH_SUFFIXES)}) in the job folder")
    if len(entries) > limits.max_parts:
        raise ConfigError(
            manifest_path if manifest.parts else folder,
            f"{len(entries)} parts, more than limits.max_parts ({limits.max_parts})",
        )
    checked, total = [], 0
    for number, entry in enumerate(entries):
        where = f"parts.{number}.file" if manifest.parts else entry.file
        path = inside(folder, entry.file)
        if path is None:
            what = (
                "symlink pointing outside the job folder"
                if (folder / entry.file).is_symlink()
                else "path leaves the job folder"
            )
            raise ConfigError(
                manifest_path if manifest.parts else folder / entry.file, f"{where}: {entry.file!r}: {what}"
            )
        if not path.is_file():
            raise ConfigError(manifest_path, f"{where}: {entry.file!r}: file not found in the job folder")
        if not is_mesh(entry.file):
            raise MeshError(path, f"unsupported file type {path.suffix!r} (use {', '.join(MESH_SUFFIXES)})")
        size = path.stat().st_size
        if size > limits.max_file_bytes:
            raise MeshError(path, f"{size} bytes, more than limits.max_file_bytes ({limits.max_file_bytes})")
        total += size
        if total > limits.max_job_bytes:
            raise MeshError(path, f"the job's parts exceed limits.max_job_bytes ({limits.max_job_bytes}) bytes")
        suffix = path.suffix.lower()
        if suffix == ".stl":
            _check_stl_faces(path, limits.max_faces)
        elif suffix == ".3mf":
            _check_3mf(path, limits)
        checked.append(PartInput(entry, path))
    return checked


def _check_stl_faces(path: Path, max_faces: int) -> None:
    """Refuse a binary STL announcing more than ``max_faces`` triangles (its header says so without parsing)."""
    with open(path, "rb") as stream:
        head = stream.read(84)
    if head[:5].lower() == b"solid" or len(head) < 84:
        return
    count = int(np.frombuffer(head[80:84], dtype="<u4")[0])
    if count > max_faces:
        raise MeshError(path, f"{count} triangles, more than limits.max_faces ({max_faces})")


def _check_3mf(path: Path, limits: LimitsConfig) -> None:
    """Refuse a 3MF whose zip entries would inflate beyond the limits (a zip bomb), from the zip directory alone."""
    try:
        with zipfile.ZipFile(path) as archive:
            entries = archive.infolist()
    except (zipfile.BadZipFile, OSError) as exc:
        raise MeshError(path, f"not a valid 3MF (zip) file: {exc}") from None
    total = sum(e.file_size for e in entries)
    if total > limits.max_3mf_uncompressed_bytes:
        raise MeshError(
            path,
            f"3MF entries inflate to {total} bytes, more than limits.max_3mf_uncompressed_bytes "
            f"({limits.max_3mf_uncompressed_bytes})",
        )
    for entry in entries:
        if entry.compress_size and entry.file_size / entry.compress_size > limits.max_3mf_ratio:
            raise MeshError(
                path,
                f"3MF entry {entry.filename!r} inflates {entry.file_size / entry.compress_size:.0f}x, "
                f"more than limits.max_3mf_ratio ({limits.max_3mf_ratio:g}): refused as a zip bomb",
            )
