"""An operator's decision on a held job in its record: ``job.mcap`` finished again with the decision appended."""

from __future__ import annotations

import os
from pathlib import Path

from ..bus.messages import DecisionRecord, StateChangeRecord
from ..config import McapConfig
from .recorder import JOB_RECORD_NAME, TOPIC_DECISION, TOPIC_STATE, salvage


def record_decision(out_dir: Path, decision: DecisionRecord, error: str | None, mcap: McapConfig) -> None:
    """Append ``decision`` and the job's new state (done when approved, failed with ``error`` when rejected) to the
    record ``job.mcap`` in ``out_dir``, in place.

    Every message the record holds is copied into a new record, which gets
    the decision and the state change and then takes the old one's name: a
    finished MCAP file cannot be appended to.

    Raises
    ------
    OSError
        The disk cannot take the new record (a full disk); the old record stays.
    """
    rewritten = out_dir / f".decided-{JOB_RECORD_NAME}"
    recorder = salvage(out_dir / JOB_RECORD_NAME, rewritten, mcap.compression, mcap.chunk_size_bytes)
    recorder.write(TOPIC_DECISION, decision)
    state = "done" if decision.decision == "approved" else "failed"
    recorder.write(TOPIC_STATE, StateChangeRecord(job_id=decision.job_id, state=state, at=decision.at, error=error))
    recorder.finish()
    os.replace(rewritten, out_dir / JOB_RECORD_NAME)
