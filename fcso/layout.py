"""The layout of an output folder, in one place, and the one way files are written into it.

One design (or a job served by one finger set)::

    out/finger.stl           the finger (both gripper fingers are this part)
    out/fingerpad.stl        the chosen pad alone, pad frame
    out/report.json          DesignReport
    out/report.html

A job served by two or more finger sets::

    out/report.json          JobReport: sets, E, E*, retained, pick plan
    out/report.html          the same for people, with every set's finger
    out/set-1/finger.stl     set 1's finger
    out/set-1/fingerpad.stl
    out/set-1/report.json    set 1's own design report (DesignReport)
    out/set-1/report.html
    out/set-2/...
"""

from __future__ import annotations

import os
from pathlib import Path

FINGER_STL = "finger.stl"
FINGERPAD_STL = "fingerpad.stl"
REPORT_JSON = "report.json"
REPORT_HTML = "report.html"
#: The verification's result (fcso.sim), beside a design's report.
VERIFICATION_JSON = "verification.json"


def set_folder(number: int, several: bool = True) -> str:
    """Folder of finger set ``number`` (from 1), relative to the output folder: ``set-<k>``, or ``.`` when one set
    serves the job.
    """
    return f"set-{number}" if several else "."


def set_finger_path(number: int, several: bool = True) -> str:
    """``finger.stl`` of finger set ``number``, relative to the output folder."""
    return f"{set_folder(number)}/{FINGER_STL}" if several else FINGER_STL


def write_atomic(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` under a temporary name beside it, then rename it into place.

    A reader sees the old file or the whole new one, never a part; the
    folder is made when missing. Returns ``path``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.parent / f".{path.name}.tmp"
    temporary.write_bytes(data)
    os.replace(temporary, path)
    return path
