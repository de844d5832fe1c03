"""JSON Schemas of the pydantic models, as written into ``schemas/``."""

from __future__ import annotations

import json
from pathlib import Path

from pydantic import BaseModel

from .config import DesignConfig
from .report.models import DesignReport, JobReport
from .sim.report import VerificationReport

#: fcso's documents: file name -> model.
FCSO_SCHEMAS: dict[str, type[BaseModel]] = {
    "design-config.json": DesignConfig,
    "design-report.json": DesignReport,
    "design-job-report.json": JobReport,
    "verification-report.json": VerificationReport,
}


def schema_text(model: type[BaseModel]) -> str:
    """The model's JSON Schema as stable, indented text ending in a newline."""
    return json.dumps(model.model_json_schema(), indent=2, sort_keys=True) + "\n"


def write_schemas(out_dir: str | Path, schemas: dict[str, type[BaseModel]] = FCSO_SCHEMAS) -> list[Path]:
    """Write one JSON Schema file per model into ``out_dir``; return the paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, model in schemas.items():
        path = out_dir / name
        path.write_text(schema_text(model), encoding="utf-8")
        written.append(path)
    return written
