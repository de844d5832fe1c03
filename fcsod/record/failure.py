"""A failed job's record: a cut-off ``job.mcap`` finished with the failure, one way for the worker and the daemon."""

from __future__ import annotations

import os
from pathlib import Path

from ..bus.messages import BusMessage, LogRecord, StateChangeRecord
from ..bus.ros2 import record_ros2
from ..config import McapConfig, Ros2Config
from .recorder import JOB_RECORD_NAME, TOPIC_BUS, TOPIC_LOG, TOPIC_STATE, salvage


def record_failure(
    work_dir: Path, job_id: str, error: str, status: BusMessage, finished_at: str, mcap: McapConfig, ros2: Ros2Config
) -> None:
    """Finish a job's cut-off record with its failure, in place.

    What ``job.mcap`` in ``work_dir`` holds is salvaged into a new record,
    which gets the error, the ``failed`` status (bus and ROS 2 channels) and
    the state change, and then takes the old one's name.

    Raises
    ------
    OSError
        The disk cannot take the new record (a full disk).
    """
    salvaged = work_dir / f"salvaged-{JOB_RECORD_NAME}"
    recorder = salvage(work_dir / JOB_RECORD_NAME, salvaged, mcap.compression, mcap.chunk_size_bytes)
    recorder.write(TOPIC_LOG, LogRecord(level="error", message=error))
    recorder.write(TOPIC_BUS, status.record())
    record_ros2(recorder, status, ros2)
    recorder.write(TOPIC_STATE, StateChangeRecord(job_id=job_id, state="failed", at=finished_at, error=error))
    recorder.finish()
    os.replace(salvaged, work_dir / JOB_RECORD_NAME)
