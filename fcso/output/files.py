"""The files of a design or of a job's finger sets (layout: :mod:`fcso.layout`), written and rebuilt."""

from __future__ import annotations

from pathlib import Path

from ..errors import MeshError
from ..layout import FINGER_STL, FINGERPAD_STL, REPORT_HTML, REPORT_JSON, set_folder, write_atomic
from ..pipeline import DesignResult
from ..progress import Progress
from ..report.models import JobReport
from ..sets import SetsResult
from .design_page import DrawPictures, rebuild_report, report_html
from .read import read_stl
from .sets_page import job_html


def output_files(
    result: DesignResult, progress: Progress | None = None, draw: DrawPictures | None = None
) -> dict[str, bytes]:
    """The files of a design.

    Parameters
    ----------
    result : DesignResult
    progress : callable, optional
        ``progress(stage, done, total)`` while the pictures of ``report.html`` render.
    draw : callable, optional
        Draws the page's pictures (:func:`fcso.output.design_page.pictures` when None).

    Returns
    -------
    dict
        ``finger.stl``, ``fingerpad.stl`` (binary STL), ``report.json`` and
        ``report.html`` (self-contained page with pictures): name -> bytes.
    """
    return {
        FINGER_STL: result.finger.export(file_type="stl"),
        FINGERPAD_STL: result.fingerpad.export(file_type="stl"),
        REPORT_JSON: (result.report.model_dump_json(indent=2) + "\n").encode("utf-8"),
        REPORT_HTML: report_html(result, progress, draw),
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
    return [write_atomic(out_dir / name, data) for name, data in output_files(result, progress).items()]


def sets_output_files(
    result: SetsResult, progress: Progress | None = None, draw: DrawPictures | None = None
) -> dict[str, bytes]:
    """The files of a job's finger sets: relative path -> bytes (see the module's layout).

    ``draw`` draws each design page's pictures (:func:`fcso.output.design_page.pictures` when None).
    """
    if not result.several:
        return output_files(result.designs[0], progress, draw)
    files = {
        f"{set_folder(k)}/{name}": data
        for k, design in enumerate(result.designs, start=1)
        for name, data in output_files(design, progress, draw).items()
    }
    files[REPORT_JSON] = (result.job_report.model_dump_json(indent=2) + "\n").encode("utf-8")
    files[REPORT_HTML] = job_html(result.job_report, [d.finger for d in result.designs]).encode("utf-8")
    return files


def write_set_outputs(
    result: SetsResult, out_dir: str | Path, progress: Progress | None = None, draw: DrawPictures | None = None
) -> list[Path]:
    """Write :func:`sets_output_files` into ``out_dir``, each under a temporary name renamed into place; return the
    paths.
    """
    out_dir = Path(out_dir)
    return [write_atomic(out_dir / name, data) for name, data in sets_output_files(result, progress, draw).items()]


def rebuild_job_report(directory: str | Path, progress: Progress | None = None) -> list[Path]:
    """Rebuild every set's ``report.html`` and the job's from the files of a job folder.

    Returns
    -------
    list of Path
        The pages written, the job's last.

    Raises
    ------
    MeshError
        A report or finger file is missing or unreadable (named in the message).
    """
    directory = Path(directory)
    path = directory / REPORT_JSON
    try:
        report = JobReport.model_validate_json(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise MeshError(path, f"not a job report: {str(exc).splitlines()[0]}") from None
    written = [rebuild_report(directory / entry.folder, progress) for entry in report.finger_sets.sets]
    fingers = [read_stl(directory / entry.folder / FINGER_STL) for entry in report.finger_sets.sets]
    return written + [write_atomic(directory / REPORT_HTML, job_html(report, fingers).encode("utf-8"))]
