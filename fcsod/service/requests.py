"""The operators' requests to the daemon: ``fcsod retry | cancel | approve | reject``, read from the journal, acted
on and answered there.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

from ..bus.messages import BusMessage, BusRecord, DecisionRecord, InputFile, StatusMessage, utc_now
from ..config import DaemonConfig
from ..job.inputs import hash_inputs, job_id, job_inputs
from ..job.task import BUILD_NAME, HELD_BUILD_NAME
from ..record.decision import record_decision
from ..record.recorder import JOB_RECORD_NAME, TOPIC_BUS, read_record
from ..storage import file_sha256
from .journal import Journal, OperatorRequest

log = logging.getLogger("fcsod")

#: The error of a job an operator cancelled (``fcsod cancel``).
CANCELLED_ERROR = "cancelled by the operator (fcsod cancel)"

#: The error of a held job an operator rejected (``fcsod reject``), before the reason it was held.
REJECTED_ERROR = "rejected by the operator (fcsod reject)"

#: Folder of ``[output] root`` where ``fcsod retry`` keeps the records of the failed runs it replaces:
#: ``attempts/<job_id>/<n>/job.mcap``.
ATTEMPTS_DIR = "attempts"


class OperatorRequests:
    """The daemon's answers to its operators' requests (a part of :class:`fcsod.service.daemon.Daemon`).

    They act through the daemon's journal, worker slots and output root, and
    its ``publish``, ``status``, ``fail_dead_job`` and ``collect``.
    """

    config: DaemonConfig
    output_root: Path
    journal: Journal
    slots: list

    def handle_requests(self) -> None:
        """Act on the operators' ``fcsod retry | cancel | approve | reject`` requests and answer each in the journal."""
        actions = {"retry": self._retry, "cancel": self._cancel, "approve": self._approve, "reject": self._reject}
        for request in self.journal.pending_requests():
            act = actions[request.action]
            accepted, outcome = act(request)
            self.journal.answer_request(request.request_id, utc_now(), accepted, outcome)
            log.info(
                f"operator request: {outcome}",
                extra={"job_id": request.job_id, "action": request.action, "accepted": accepted},
            )

    def _retry(self, request: OperatorRequest) -> tuple[bool, str]:
        """Queue a failed job again; the failed run's output folder moves to ``attempts/<job_id>/<n>/``."""
        row = self.journal.get(request.job_id)
        if row is None:
            return False, f"{request.job_id}: no such job"
        if row.state != "failed":
            return False, f"{row.job_id} is {row.state}: only a failed job can be retried"
        folder = Path(row.folder)
        if not folder.is_dir():
            return False, f"{row.job_id}: its job folder {folder} no longer exists"
        hashed = hash_inputs(folder, job_inputs(folder), self.config.limits.max_file_bytes)
        current = job_id(folder.name, hashed)
        if current != row.job_id:
            # the content is the job's identity: changed inputs are another job, which the watcher queues itself
            return False, f"{row.job_id}: the inputs in {folder} changed since: they are job {current}"
        previous = self.output_root / row.job_id
        kept = None
        if previous.exists():
            attempts = self.output_root / ATTEMPTS_DIR / row.job_id
            attempts.mkdir(parents=True, exist_ok=True)
            kept = attempts / str(len(list(attempts.iterdir())) + 1)
            os.replace(previous, kept)
        self.journal.requeue_failed(row.job_id, utc_now())
        self.publish(self.status(self.journal.get(row.job_id)))
        return True, f"{row.job_id} queued again" + (f"; the failed run's record is kept in {kept}" if kept else "")

    def _cancel(self, request: OperatorRequest) -> tuple[bool, str]:
        """End a queued or running job ``failed`` with :data:`CANCELLED_ERROR`; a running job's worker is killed."""
        row = self.journal.get(request.job_id)
        if row is None:
            return False, f"{request.job_id}: no such job"
        if row.state == "queued":
            self.fail_dead_job(row, CANCELLED_ERROR)
            return True, f"{row.job_id} cancelled before it started"
        running = next((s for s in self.slots if s.job is not None and s.job.job_id == row.job_id), None)
        if row.state != "running" or running is None or running.finished:
            return False, f"{row.job_id} is {row.state}: only a queued or running job can be cancelled"
        # the worker is killed at once and the job failed with this error, keeping its record so far
        running.stop_error = CANCELLED_ERROR
        running.process.kill()
        running.process.join()
        self.collect(running)
        ended = self.journal.get(row.job_id)
        if ended.error != CANCELLED_ERROR:
            return False, f"{row.job_id} ended {ended.state} before it could be cancelled"
        return True, f"{row.job_id} cancelled while running"

    def _decision(self, request: OperatorRequest, files: dict[str, Path], removed: list[str]) -> DecisionRecord:
        """The record of an operator's ``request`` on a held job that writes the output ``files`` (name -> the file
        that will have that name) and removes the outputs named ``removed``."""
        return DecisionRecord(
            job_id=request.job_id,
            decision="approved" if request.action == "approve" else "rejected",
            by=request.requested_by or "unknown (a request of an older fcsod)",
            requested_at=request.requested_at,
            at=utc_now(),
            files=[
                InputFile(path=name, size_bytes=path.stat().st_size, sha256=file_sha256(path))
                for name, path in files.items()
            ],
            removed=removed,
        )

    def _approve(self, request: OperatorRequest) -> tuple[bool, str]:
        """Release a held job: its build with the finger placed becomes ``build.3mf``, its design messages (in its
        record) are published, and it is done; its record gets the approval, with the new build's hash."""
        row = self.journal.get(request.job_id)
        if row is None:
            return False, f"{request.job_id}: no such job"
        if row.state != "held":
            return False, f"{row.job_id} is {row.state}: only a held job can be approved"
        out = self.output_root / row.job_id
        recorded = [
            BusMessage.from_record(BusRecord.model_validate(body))
            for body in read_record(out / JOB_RECORD_NAME).of(TOPIC_BUS)
        ]
        held = next(StatusMessage.model_validate_json(m.payload) for m in reversed(recorded) if m.topic == "status")
        approval = self._decision(request, {BUILD_NAME: out / HELD_BUILD_NAME}, [HELD_BUILD_NAME])
        record_decision(out, approval, None, self.config.mcap)
        os.replace(out / HELD_BUILD_NAME, out / BUILD_NAME)
        self.journal.mark_finished(row.job_id, "done", row.finished_at or utc_now(), None)
        for message in recorded:
            if withheld(message):
                self.publish(message)
        outputs = [name for name in held.outputs if name != HELD_BUILD_NAME]
        done = held.model_copy(update={"state": "done", "error": None, "outputs": outputs})
        self.publish(BusMessage.json_body(self.config.bus.prefix, self.config.bus.cell, "status", done))
        return True, f"{row.job_id} approved: its finger is placed into {out / BUILD_NAME} and its grasps published"

    def _reject(self, request: OperatorRequest) -> tuple[bool, str]:
        """Fail a held job with :data:`REJECTED_ERROR` and why it was held; its build with the finger is removed, and
        its record gets the rejection."""
        row = self.journal.get(request.job_id)
        if row is None:
            return False, f"{request.job_id}: no such job"
        if row.state != "held":
            return False, f"{row.job_id} is {row.state}: only a held job can be rejected"
        out = self.output_root / row.job_id
        error = f"{REJECTED_ERROR}: {row.error}"
        record_decision(out, self._decision(request, {}, [HELD_BUILD_NAME]), error, self.config.mcap)
        (out / HELD_BUILD_NAME).unlink(missing_ok=True)
        self.journal.mark_finished(row.job_id, "failed", utc_now(), error)
        self.publish(self.status(self.journal.get(row.job_id)))
        return True, f"{row.job_id} rejected: it is failed, its finger is not delivered"


def withheld(message: BusMessage) -> bool:
    """A message of a held job that waits for ``fcsod approve``: everything but its status and its verification."""
    return message.topic != "status" and message.topic.partition("/")[0] != "verification"
