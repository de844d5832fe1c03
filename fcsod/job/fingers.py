"""The cell's finger library (METHOD §11b): the finger sets the daemon delivered, to reuse for jobs of the same parts.

One SQLite file, ``<state_dir>/fingers.sqlite3``, next to the journal and
written the same way (WAL, every commit synced, so a ``kill -9`` loses no
delivered finger). A finger is kept with the geometry of every part it
serves (vertices and triangles in mm, moved so their bounding box starts at
the origin, as :func:`fcso.sets.identity.same_geometry` compares them), the
grasps of those parts, the finger STL and its sha256, its pad alone (pad
frame), the settings it and its grasps were designed with, and the jobs it
served. A finger serves only jobs of the same settings (a finger kept before
the library recorded them serves none).
Workers of concurrent jobs open it each on their own connection; a reuse
claims its fingers in one write transaction, so the wear count cannot be
passed by two jobs at once.
"""

from __future__ import annotations

import hashlib
import io
import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from fcso.report.models import GraspReport

from ..bus.messages import utc_now
from ..config import DaemonConfig
from ..storage import connect_database

if TYPE_CHECKING:
    import trimesh

#: The library's file in the daemon's state folder.
LIBRARY_NAME = "fingers.sqlite3"


def library_path(config: DaemonConfig) -> Path:
    """The cell's finger library in the daemon's state folder."""
    return config.state.dir / LIBRARY_NAME


_SCHEMA = """
CREATE TABLE IF NOT EXISTS fingers (
    finger_id      INTEGER PRIMARY KEY AUTOINCREMENT,
    cell           TEXT NOT NULL,
    job_id         TEXT NOT NULL,
    finger_set     INTEGER NOT NULL,
    finger_file    TEXT NOT NULL,
    design_key     TEXT NOT NULL,
    sha256         TEXT NOT NULL,
    finger_stl     BLOB NOT NULL,
    quality        REAL NOT NULL,
    quality_measure TEXT NOT NULL DEFAULT 'capture',
    worst_retained REAL NOT NULL,
    created_at     TEXT NOT NULL,
    retired_at     TEXT,
    pad_stl        BLOB,
    design_settings TEXT,
    UNIQUE (job_id, finger_set)
);
CREATE TABLE IF NOT EXISTS finger_parts (
    finger_id  INTEGER NOT NULL REFERENCES fingers (finger_id),
    part       TEXT NOT NULL,
    faces      INTEGER NOT NULL,
    vertices   INTEGER NOT NULL,
    volume_mm3 REAL NOT NULL,
    geometry   BLOB NOT NULL,
    min_corner TEXT NOT NULL,
    grasps     TEXT NOT NULL,
    PRIMARY KEY (finger_id, part)
);
CREATE TABLE IF NOT EXISTS served (
    finger_id INTEGER NOT NULL REFERENCES fingers (finger_id),
    job_id    TEXT NOT NULL,
    served_at TEXT NOT NULL,
    PRIMARY KEY (finger_id, job_id)
);
"""


@dataclass
class DeliveredPart:
    """A part a delivered finger serves.

    Attributes
    ----------
    name : str
        The part's name in the job that delivered the finger.
    mesh : trimesh.Trimesh
        The part in mm, in its file's frame (after units and shell union).
    grasps : list of GraspReport
        The part's grasps with this finger (rest transforms from this frame).
    """

    name: str
    mesh: trimesh.Trimesh
    grasps: list[GraspReport]


@dataclass
class DeliveredFinger:
    """One finger set a done job delivered: what the library keeps of it.

    ``design_settings`` is the JSON of the settings sections the finger and its
    grasps were designed with (:func:`fcsod.job.reuse.finger_settings`): it
    serves only jobs whose own are the same. ``pad_stl`` is the pad alone in
    its pad frame (:attr:`fcso.DesignResult.fingerpad`): with it, the finger
    can be evaluated on parts that are not the same (:func:`fcso.fit_pads`).
    """

    job_id: str
    finger_set: int
    finger_file: str
    design_key: str
    finger_stl: bytes
    quality: float
    quality_measure: str
    worst_retained: float
    parts: list[DeliveredPart]
    design_settings: str
    pad_stl: bytes | None = None


@dataclass
class FingerEntry:
    """A library entry as ``fcsod fingers list`` shows it."""

    finger_id: int
    cell: str
    job_id: str
    finger_set: int
    finger_file: str
    design_key: str
    sha256: str
    quality: float
    quality_measure: str
    worst_retained: float
    created_at: str
    retired_at: str | None
    jobs: int
    parts: list[str]


@dataclass
class ServedPart:
    """How the library serves one part of a new job.

    Attributes
    ----------
    finger : FingerEntry
        The finger that serves it.
    library_part : str or None
        The part of the same geometry in the job that delivered the finger;
        None when the part is served because it keeps ``min_retained`` on it.
    grasps : list of GraspReport
        Named for the new part, rest transforms from the new part's file
        frame: the delivered grasps moved, or the part's best grasps on the finger.
    worst_retained : float or None
        With ``library_part`` None: the smallest ``E / E*`` of the part's scenarios on the finger.
    """

    finger: FingerEntry
    library_part: str | None
    grasps: list[GraspReport]
    worst_retained: float | None = None


@dataclass
class FittedPart:
    """A part of a new job that keeps at least ``min_retained`` on a library finger (:func:`fcso.fit_pads`).

    Attributes
    ----------
    finger_id : int
    worst_retained : float
        The smallest ``E / E*`` of the part's scenarios on the finger.
    grasps : list of GraspReport
        The part's best grasps on the finger, rest transforms from its file frame.
    """

    finger_id: int
    worst_retained: float
    grasps: list[GraspReport]


class FingerLibrary:
    """The library in ``<state_dir>/fingers.sqlite3`` (created if missing).

    Parameters
    ----------
    path : Path
        The database file.
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._db = connect_database(self.path)
        self._db.executescript(_SCHEMA)
        columns = {row[1] for row in self._db.execute("PRAGMA table_info(fingers)")}
        with self._db:
            # a library written before qualities named their measure: its qualities are the default measure's
            if "quality_mm2" in columns:
                self._db.execute("ALTER TABLE fingers RENAME COLUMN quality_mm2 TO quality")
            # ... and before pads and the design's settings were kept: its fingers serve no job (their settings
            # are unknown), ``fcsod fingers list`` still lists them
            for column, kind in (
                ("quality_measure", "TEXT NOT NULL DEFAULT 'capture'"),
                ("pad_stl", "BLOB"),
                ("design_settings", "TEXT"),
            ):
                if column not in columns:
                    self._db.execute(f"ALTER TABLE fingers ADD COLUMN {column} {kind}")

    def close(self) -> None:
        self._db.close()

    def add(self, cell: str, finger: DeliveredFinger) -> int:
        """Keep a delivered finger; it counts its own job as served. A job run again adds nothing. Returns its id."""
        with self._db:
            self._db.execute(
                "INSERT OR IGNORE INTO fingers (cell, job_id, finger_set, finger_file, design_key, sha256, finger_stl, "
                "quality, quality_measure, worst_retained, created_at, pad_stl, design_settings) "
                "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    cell,
                    finger.job_id,
                    finger.finger_set,
                    finger.finger_file,
                    finger.design_key,
                    hashlib.sha256(finger.finger_stl).hexdigest(),
                    finger.finger_stl,
                    finger.quality,
                    finger.quality_measure,
                    finger.worst_retained,
                    utc_now(),
                    finger.pad_stl,
                    finger.design_settings,
                ),
            )
            finger_id = self._db.execute(
                "SELECT finger_id FROM fingers WHERE job_id = ? AND finger_set = ?", (finger.job_id, finger.finger_set)
            ).fetchone()[0]
            for part in finger.parts:
                vertices = np.asarray(part.mesh.vertices, dtype=np.float64)
                corner = vertices.min(axis=0)
                self._db.execute(
                    "INSERT OR IGNORE INTO finger_parts VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                    (
                        finger_id,
                        part.name,
                        len(part.mesh.faces),
                        len(vertices),
                        float(part.mesh.volume),
                        _geometry_blob(vertices - corner, np.asarray(part.mesh.faces, dtype=np.int64)),
                        json.dumps(corner.tolist()),
                        json.dumps([g.model_dump(mode="json") for g in part.grasps]),
                    ),
                )
            self._db.execute("INSERT OR IGNORE INTO served VALUES (?, ?, ?)", (finger_id, finger.job_id, utc_now()))
        return finger_id

    def entries(self, cell: str | None = None) -> list[FingerEntry]:
        """Every finger (of ``cell``, or of all cells), oldest first."""
        rows = self._db.execute(
            "SELECT finger_id, cell, job_id, finger_set, finger_file, design_key, sha256, quality, quality_measure, "
            "worst_retained, "
            "created_at, retired_at, (SELECT COUNT(*) FROM served s WHERE s.finger_id = f.finger_id) FROM fingers f "
            + ("WHERE cell = ? " if cell is not None else "")
            + "ORDER BY finger_id",
            (cell,) if cell is not None else (),
        ).fetchall()
        parts = {}
        for finger_id, name in self._db.execute("SELECT finger_id, part FROM finger_parts ORDER BY rowid"):
            parts.setdefault(finger_id, []).append(name)
        return [FingerEntry(*row, parts=parts.get(row[0], [])) for row in rows]

    def finger_stl(self, finger_id: int) -> bytes:
        """The STL of a finger in the library."""
        return self._db.execute("SELECT finger_stl FROM fingers WHERE finger_id = ?", (finger_id,)).fetchone()[0]

    def retire(self, finger_id: int) -> bool:
        """Take a finger out of use (worn or lost); False when there is no such active finger."""
        with self._db:
            cursor = self._db.execute(
                "UPDATE fingers SET retired_at = ? WHERE finger_id = ? AND retired_at IS NULL", (utc_now(), finger_id)
            )
        return cursor.rowcount == 1

    def claim(
        self,
        cell: str,
        job_id: str,
        meshes: dict[str, trimesh.Trimesh],
        reprint_after_jobs: int,
        design_settings: str,
        fitted: dict[str, FittedPart] | None = None,
    ) -> dict[str, ServedPart] | None:
        """Serve every part of a job from the library, and count the job on the fingers that serve it.

        Parameters
        ----------
        cell : str
            Only this cell's fingers serve.
        job_id : str
            The new job; a finger it delivered itself (a job run again) does not serve it.
        meshes : dict
            Part name -> part mesh in mm, file frame (:func:`fcso.load_parts`).
        reprint_after_jobs : int
            A finger that served this many jobs is worn: it serves no more.
        design_settings : str
            The job's settings (:func:`fcsod.job.reuse.finger_settings`):
            only a finger designed with the same serves it.
        fitted : dict, optional
            Part name -> a finger the part keeps ``min_retained`` on, for
            parts that are not the same as a delivered part.

        Returns
        -------
        dict or None
            Part name -> how it is served; None (and nothing counted) unless
            every part has the same geometry as a part of an active finger of
            the same settings (the newest such finger serves it) or is fitted
            to one still active.
        """
        with self._db:
            # one write transaction: concurrent jobs see each other's claims
            self._db.execute("BEGIN IMMEDIATE")
            entries = self._active(cell, job_id, reprint_after_jobs, design_settings)
            served = {}
            for name, mesh in meshes.items():
                match = self._serving(list(entries), mesh)
                fit = (fitted or {}).get(name)
                if match is not None:
                    finger_id, library_part, corner, grasps = match
                    shift = np.asarray(mesh.vertices, dtype=np.float64).min(axis=0) - corner
                    served[name] = ServedPart(
                        entries[finger_id], library_part, [_moved(g, name, shift) for g in grasps]
                    )
                elif fit is not None and fit.finger_id in entries:
                    grasps = [g.model_copy(update={"part": name}) for g in fit.grasps]
                    served[name] = ServedPart(entries[fit.finger_id], None, grasps, fit.worst_retained)
                else:
                    return None
            at = utc_now()
            for finger_id in sorted({s.finger.finger_id for s in served.values()}):
                self._db.execute("INSERT OR IGNORE INTO served VALUES (?, ?, ?)", (finger_id, job_id, at))
                entries[finger_id].jobs = len(self._served(finger_id))
        return served

    def near_fingers(
        self,
        cell: str,
        job_id: str,
        meshes: dict[str, trimesh.Trimesh],
        reprint_after_jobs: int,
        design_settings: str,
        size_percent: float,
    ) -> dict[str, list[int]] | None:
        """The fingers worth evaluating for the parts no delivered part has the geometry of.

        Parameters
        ----------
        cell, job_id, meshes, reprint_after_jobs, design_settings
            As for :meth:`claim`: a finger designed with other settings is not evaluated.
        size_percent : float
            A finger is evaluated for a part when one of its parts has every
            bounding-box side (sorted) and the volume within this percentage.

        Returns
        -------
        dict or None
            Part name -> active fingers with a pad to evaluate it on, newest
            first, for every part not of a delivered geometry; None when a part
            has neither (the library cannot serve the job).
        """
        entries = self._active(cell, job_id, reprint_after_jobs, design_settings)
        with_pad = [
            r[0]
            for r in self._db.execute("SELECT finger_id FROM fingers WHERE pad_stl IS NOT NULL ORDER BY finger_id DESC")
            if r[0] in entries
        ]
        kept = [
            (finger_id, _sides(_geometry_mesh(geometry)), volume)
            for finger_id, geometry, volume in self._db.execute(
                "SELECT finger_id, geometry, volume_mm3 FROM finger_parts WHERE finger_id IN ("
                + ",".join("?" * len(with_pad))
                + ")",
                with_pad,
            )
        ]
        near = {}
        for name, mesh in meshes.items():
            if self._serving(list(entries), mesh) is not None:
                continue
            sides, volume = _sides(mesh), float(mesh.volume)
            fingers = {
                finger_id
                for finger_id, kept_sides, kept_volume in kept
                if np.all(np.abs(sides - kept_sides) <= size_percent / 100 * kept_sides)
                and abs(volume - kept_volume) <= size_percent / 100 * abs(kept_volume)
            }
            if not fingers:
                return None
            near[name] = sorted(fingers, reverse=True)
        return near

    def pad(self, finger_id: int) -> trimesh.Trimesh:
        """The pad alone of a library finger, its pad frame (mm)."""
        import trimesh  # loaded where a mesh is made: `fcsod fingers list` makes none

        blob = self._db.execute("SELECT pad_stl FROM fingers WHERE finger_id = ?", (finger_id,)).fetchone()[0]
        return trimesh.load(io.BytesIO(blob), file_type="stl")

    def other_settings(
        self, cell: str, job_id: str, meshes: dict[str, trimesh.Trimesh], reprint_after_jobs: int, design_settings: str
    ) -> dict[int, str | None]:
        """The active fingers with a part of the geometry of one of ``meshes`` that were designed with other settings
        than ``design_settings``: finger id -> the settings they were designed with (None: not recorded).

        Parameters as for :meth:`claim`; what tells a job why such a finger does not serve it.
        """
        entries = self._active(cell, job_id, reprint_after_jobs)
        kept = dict(self._db.execute("SELECT finger_id, design_settings FROM fingers"))
        other = [i for i in entries if kept[i] != design_settings]
        matches = [self._serving(other, mesh) for mesh in meshes.values()]
        return {i: kept[i] for i in sorted({m[0] for m in matches if m is not None})}

    def _active(
        self, cell: str, job_id: str, reprint_after_jobs: int, design_settings: str | None = None
    ) -> dict[int, FingerEntry]:
        """The fingers that may serve ``job_id``: the cell's, not retired, not worn, not delivered by the job itself;
        with ``design_settings``, only those designed with them."""
        entries = {e.finger_id: e for e in self.entries(cell) if e.retired_at is None and e.job_id != job_id}
        if design_settings is not None:
            same = {
                r[0]
                for r in self._db.execute("SELECT finger_id FROM fingers WHERE design_settings = ?", (design_settings,))
            }
            entries = {i: e for i, e in entries.items() if i in same}
        return {i: e for i, e in entries.items() if e.jobs < reprint_after_jobs or job_id in self._served(i)}

    def _served(self, finger_id: int) -> set[str]:
        return {r[0] for r in self._db.execute("SELECT job_id FROM served WHERE finger_id = ?", (finger_id,))}

    def _serving(
        self, finger_ids: list[int], mesh: trimesh.Trimesh
    ) -> tuple[int, str, np.ndarray, list[GraspReport]] | None:
        """The newest of ``finger_ids`` with a part of ``mesh``'s geometry: id, part name, its corner, its grasps."""
        # fcso.sets loads the design's pipeline: not for the operator's `fcsod fingers`, which never compares
        from fcso.sets.identity import same_geometry

        if not finger_ids:
            return None
        volume = float(mesh.volume)
        rows = self._db.execute(
            "SELECT finger_id, part, geometry, min_corner, grasps FROM finger_parts WHERE faces = ? AND vertices = ? "
            "AND ABS(volume_mm3 - ?) <= 1e-6 * ABS(?) + 1e-6 AND finger_id IN ("
            + ",".join("?" * len(finger_ids))
            + ") "
            "ORDER BY finger_id DESC",
            (len(mesh.faces), len(mesh.vertices), volume, volume, *finger_ids),
        ).fetchall()
        for finger_id, part, geometry, corner, grasps in rows:
            if same_geometry(_geometry_mesh(geometry), mesh):
                return (
                    finger_id,
                    part,
                    np.array(json.loads(corner)),
                    [GraspReport.model_validate(g) for g in json.loads(grasps)],
                )
        return None


def _moved(grasp: GraspReport, part: str, shift: np.ndarray) -> GraspReport:
    """A delivered grasp for the same geometry moved by ``shift`` (mm) in its file frame, named ``part``."""
    rest = np.asarray(grasp.rest_transform, dtype=float)
    back = np.eye(4)
    back[:3, 3] = -shift
    return grasp.model_copy(update={"part": part, "rest_transform": (rest @ back).tolist()})


def _sides(mesh: trimesh.Trimesh) -> np.ndarray:
    """The bounding-box sides of a mesh, sorted, mm: the same whatever axis a file puts the part along."""
    return np.sort(np.ptp(np.asarray(mesh.vertices, dtype=np.float64), axis=0))


def _geometry_blob(vertices: np.ndarray, faces: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.savez(buffer, vertices=vertices, faces=faces)
    return buffer.getvalue()


def _geometry_mesh(blob: bytes) -> trimesh.Trimesh:
    import trimesh

    arrays = np.load(io.BytesIO(blob))
    return trimesh.Trimesh(arrays["vertices"], arrays["faces"], process=False)
