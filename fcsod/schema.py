"""JSON Schemas of fcsod's documents: config, job manifest, zenoh messages and MCAP channels (``schemas/``)."""

from __future__ import annotations

from pathlib import Path

from pydantic import BaseModel

from fcso.schema import write_schemas
from fcso.sim.report import VerificationReport

from .bus.messages import (
    DesignAttachment,
    GraspsMessage,
    PlacementMessage,
    PlanMessage,
    QualityMessage,
    SignedAttachment,
    StatusMessage,
    VerificationMessage,
)
from .config import DaemonConfig, JobManifest
from .job.reuse import ReuseReport
from .plate.models import PlacementReport
from .record.recorder import CHANNELS, TOPIC_VERIFICATION


def _channel_file(topic: str) -> str:
    return "mcap" + topic.replace("/", "-") + ".json"


#: fcsod's documents: file name -> model.
FCSOD_SCHEMAS: dict[str, type[BaseModel]] = {
    "fcsod-config.json": DaemonConfig,
    "job-manifest.json": JobManifest,
    "zenoh-status.json": StatusMessage,
    "zenoh-quality.json": QualityMessage,
    "zenoh-grasps.json": GraspsMessage,
    "zenoh-design-attachment.json": DesignAttachment,
    "zenoh-attachment.json": SignedAttachment,
    "zenoh-placement.json": PlacementMessage,
    "zenoh-plan.json": PlanMessage,
    "placement-report.json": PlacementReport,
    "reuse-report.json": ReuseReport,
    **{_channel_file(topic): model for topic, model in CHANNELS.items()},
    "zenoh-verification.json": VerificationMessage,
    _channel_file(TOPIC_VERIFICATION): VerificationReport,
}


def write_fcsod_schemas(out_dir: str | Path) -> list[Path]:
    """Write every fcsod schema into ``out_dir``; returns the paths."""
    return write_schemas(out_dir, FCSOD_SCHEMAS)
