"""``fcsod journal check | rebuild``: find a corrupt journal and rebuild it from the job records in the output folder.

Every finished job leaves ``<output_root>/<job_id>/job.mcap`` holding its
status messages and every message it published, so the journal's finished
jobs and the queryable's messages can be rebuilt from the records alone.
Jobs that had not finished have no record in the output folder: the daemon's
first rescan finds their folders and queues them again, while the finished
ones are known and not run again.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

from ..bus.messages import BusMessage, BusRecord, StatusMessage
from ..bus.signing import Signer
from ..record.recorder import JOB_RECORD_NAME, TOPIC_BUS, TOPIC_STATE, read_record
from .journal import JobRow, Journal, stored_message


@dataclass
class RebuildResult:
    """What :func:`rebuild_journal` did."""

    journal: Path
    moved_aside: Path | None
    jobs: dict[str, str] = field(default_factory=dict)
    skipped: dict[str, str] = field(default_factory=dict)


def job_row_from_record(job_id: str, record: Path) -> tuple[JobRow, list[BusMessage]]:
    """The journal row of a finished job and the messages it published (latest per topic), read from its ``job.mcap``.

    Raises
    ------
    ValueError
        The record holds no status message.
    """
    content = read_record(record)
    published = [BusMessage.from_record(BusRecord.model_validate(b)) for b in content.of(TOPIC_BUS)]
    statuses = [StatusMessage.model_validate_json(m.payload) for m in published if m.topic == "status"]
    if not statuses:
        raise ValueError(f"{record}: no status message recorded")
    last = statuses[-1]
    states = content.of(TOPIC_STATE)
    # a record in the output folder is a finished job; one that stops early (cut off) counts as failed
    state = last.state if last.state in ("done", "failed") else "failed"
    error = (
        last.error
        if state == last.state
        else f"record ends in state {last.state}" + (" (truncated)" if content.truncated else "")
    )
    finished_at = last.finished_at or (states[-1]["at"] if states else None)
    row = JobRow(job_id, last.folder, state, last.attempt, last.queued_at, last.started_at, finished_at, error)
    latest = {m.topic: m for m in published}
    return row, list(latest.values())


def rebuild_journal(journal_path: str | Path, output_root: str | Path, signer: Signer) -> RebuildResult:
    """Write a new journal from every ``<output_root>/<job_id>/job.mcap``; an existing journal file is moved aside,
    never deleted.

    Parameters
    ----------
    journal_path : path
        ``<state.dir>/journal.sqlite3``.
    output_root : path
        ``[output] root``.
    signer : Signer
        The daemon's signer: the records keep messages as the worker made them, unsigned.

    Returns
    -------
    RebuildResult
        The journal, where the old one went, each job's state, and the records that could not be read (with why).
    """
    journal_path, output_root = Path(journal_path), Path(output_root)
    moved = None
    if journal_path.exists():
        stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
        moved = journal_path.with_name(f"{journal_path.name}.corrupt-{stamp}")
        os.replace(journal_path, moved)
        for suffix in ("-wal", "-shm"):
            side = journal_path.with_name(journal_path.name + suffix)
            if side.exists():
                os.replace(side, moved.with_name(moved.name + suffix))
    result = RebuildResult(journal_path, moved)
    rows = []
    for record in sorted(output_root.glob(f"*/{JOB_RECORD_NAME}")):
        job_id = record.parent.name
        if job_id.startswith("."):
            continue
        try:
            rows.append(job_row_from_record(job_id, record))
        except (ValueError, OSError) as exc:
            result.skipped[job_id] = str(exc)
    journal = Journal(journal_path)
    try:
        for row, messages in sorted(rows, key=lambda item: item[0].queued_at or ""):
            journal.restore(row)
            for message in messages:
                journal.store_message(stored_message(signer.sign(message), output_root))
            result.jobs[row.job_id] = row.state
    finally:
        journal.close()
    return result
