"""Writing a design's files into an output folder."""

from __future__ import annotations

import os
from pathlib import Path

from .design import DesignResult, Progress
from .html_report import DrawPictures, report_html


def output_files(result: DesignResult, progress: Progress | None = None, draw: DrawPictures | None = None) -> dict[str, bytes]:
    """The files of a design.

    Parameters
    ----------
    result : DesignResult
    progress : callable, optional
        ``progress(stage, done, total)`` while the pictures of ``report.html`` render.
    draw : callable, optional
        Draws the page's pictures (:func:`fcso.html_report.pictures` when None).

    Returns
    -------
    dict
        ``finger.stl``, ``fingerpad.stl`` (binary STL), ``report.json`` and
        ``report.html`` (self-contained page with pictures): name -> bytes.
    """
    return {
        "finger.stl": result.finger.export(file_type="stl"),
        "fingerpad.stl": result.fingerpad.export(file_type="stl"),
        "report.json": (result.report.model_dump_json(indent=2) + "\n").encode("utf-8"),
        "report.html": report_html(result, progress, draw),
    }


def write_outputs(result: DesignResult, out_dir: str | Path, progress: Progress | None = None) -> list[Path]:
    """Write :func:`output_files` into ``out_dir``, each under a temporary name renamed into place.

    Returns
    -------
    list of Path
        The files written.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, data in output_files(result, progress).items():
        temporary = out_dir / f".{name}.tmp"
        temporary.write_bytes(data)
        os.replace(temporary, out_dir / name)
        written.append(out_dir / name)
    return written
