"""The batch demo job (``examples/jobs/batch-demo``): its folder, its parts and its manifest's fcso settings."""

from __future__ import annotations

from pathlib import Path

import fcso
from fcsod.config import JobManifest, parse_manifest

#: The job folder: ``job.toml`` and the part files it names.
BATCH_DEMO = Path(__file__).resolve().parent / "jobs" / "batch-demo"

#: The demo job's 10 mm pads (its ``[sampler]``): two tests pin defects found on its parts with them (the cube rocking
#: in the pads its embossed letters carve, a float32 flap on the finger of both parts), whatever pads the job takes.
DEMO_10MM_PADS = {"length_mm": 10.0, "width_mm": 10.0, "thickness_mm": 4.0, "penetration_mm": 3.0, "stride_mm": 10.0}


def batch_demo_settings() -> fcso.DesignConfig:
    """fcso's defaults with the manifest's sections applied, as the daemon would design the job."""
    return _manifest().design_config(fcso.DesignConfig())


def batch_demo_part_files() -> list[Path]:
    """The job's part files, in manifest order (each once: quantities are the pick plan's concern)."""
    return [BATCH_DEMO / entry.file for entry in _manifest().parts]


def _manifest() -> JobManifest:
    path = BATCH_DEMO / "job.toml"
    return parse_manifest(path.read_text(encoding="utf-8"), path, fcso.DesignConfig())
