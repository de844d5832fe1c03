"""Reading an output folder back: its report, its meshes and the part files the report names."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import trimesh

from ..errors import MeshError
from ..layout import FINGER_STL, FINGERPAD_STL, REPORT_JSON
from ..parts import Part, load_parts
from ..report.models import DesignReport


def read_stl(path: Path) -> trimesh.Trimesh:
    """An output STL (finger or fingerpad) with merged vertices; MeshError naming it when missing."""
    if not path.is_file():
        raise MeshError(path, "file not found")
    # merged vertices: the signed distance used for seating needs a closed mesh
    return trimesh.load(str(path), force="mesh", process=True)


def read_report(directory: str | Path) -> DesignReport:
    """``report.json`` of a design's output folder.

    Raises
    ------
    MeshError
        The file is missing.
    """
    report_path = Path(directory) / REPORT_JSON
    if not report_path.is_file():
        raise MeshError(report_path, "file not found (run fcso design --out DIR first)")
    return DesignReport.model_validate_json(report_path.read_text(encoding="utf-8"))


def reload_parts(report: DesignReport, directory: Path) -> list[Part]:
    """The report's parts read again from their files, in the report's order, mm.

    A file is read once with the scale recorded for it (a 3MF in its own unit,
    then scaled) and repaired when the design repaired it (its ``repair``
    figures, even when they list no change: the repair's reading of a file of
    several shells is not the plain reading's), and its parts are matched by
    name (a one-part file whatever its name in the report).
    """
    by_file: dict[tuple[str, float, bool], dict[str, Part]] = {}
    parts = []
    for entry in report.parts:
        path = _part_path(entry.file, directory)
        key = (str(path), entry.scale_to_mm, entry.repair is not None)
        if key not in by_file:
            is_3mf = path.suffix.lower() == ".3mf"
            loaded = load_parts(path, units=1.0 if is_3mf else entry.scale_to_mm, repair=entry.repair is not None)
            for part in loaded:
                if is_3mf and entry.scale_to_mm != 1.0:
                    part.mesh.apply_scale(entry.scale_to_mm)
            by_file[key] = {part.name: part for part in loaded}
        found = by_file[key]
        if entry.name in found:
            parts.append(found[entry.name])
        elif len(found) == 1:
            # a one-part file designed under another name
            parts.append(next(iter(found.values())))
        else:
            raise MeshError(path, f"holds no part named {entry.name!r} any more (the file changed since the design)")
    return parts


def _part_path(file: str, directory: Path) -> Path:
    """A part file as recorded, or relative to the output folder when the recorded path is gone."""
    recorded = Path(file)
    if recorded.is_file() or recorded.is_absolute():
        return recorded
    beside = directory / recorded
    return beside if beside.is_file() else recorded


def is_job_folder(directory: str | Path) -> bool:
    """Whether ``directory`` holds the output of a job with several finger sets (its ``report.json`` is a JobReport)."""
    path = Path(directory) / REPORT_JSON
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(data, dict) and "finger_sets" in data and "best" not in data


@dataclass
class DesignFolder:
    """A design's output folder read back.

    Attributes
    ----------
    report : DesignReport
    finger, fingerpad : trimesh.Trimesh
        ``finger.stl`` (finger frame) and ``fingerpad.stl`` (pad frame), mm, vertices merged.
    parts : list of Part
        The report's parts read again from their files, in its order, mm.
    """

    report: DesignReport
    finger: trimesh.Trimesh
    fingerpad: trimesh.Trimesh
    parts: list[Part]


def read_design_folder(directory: str | Path) -> DesignFolder:
    """``report.json``, ``finger.stl``, ``fingerpad.stl`` and the part files the report names.

    Raises
    ------
    MeshError
        A file is missing or unreadable (named in the message).
    """
    directory = Path(directory)
    report = read_report(directory)
    finger = read_stl(directory / FINGER_STL)
    fingerpad = read_stl(directory / FINGERPAD_STL)
    return DesignFolder(report, finger, fingerpad, reload_parts(report, directory))
