"""Running one job start to end, and what happens when it fails: the record always finishes, the folder always moves
into place.
"""

from __future__ import annotations

import errno
import os
import shutil
import time
import traceback
from pathlib import Path

from fcso import FcsoError

from ..bus.messages import BusMessage, StateChangeRecord, utc_now
from ..record.failure import record_failure
from ..record.recorder import JOB_RECORD_NAME, TOPIC_STATE, Recorder
from .events import Emit, JobFinished, Log, Publish, StepFinished
from .steps import job_steps
from .task import JobFolderDeleted, JobRun, JobTask, TimeLimitExceeded, Withdrawn, status_message, time_limit_error
from .verification import verification_after_done, verify_done_job


def run_job(task: JobTask, emit: Emit) -> None:
    """Run one job start to end; always leaves a finished ``job.mcap`` in the job's output folder.

    Parameters
    ----------
    task : JobTask
    emit : callable
        Receives :class:`~fcsod.job.events.Log`, :class:`~fcsod.job.events.Publish`,
        :class:`~fcsod.job.events.StepFinished` after each step, :class:`~fcsod.job.events.Scene` for each scene,
        and one :class:`~fcsod.job.events.JobFinished`; then, when a verification follows, what
        :func:`~fcsod.job.verification.verify_done_job` sends.
    """
    config = task.config
    output_root = config.output.root
    work_dir = output_root / f".tmp-{task.job_id}"
    final_dir = output_root / task.job_id
    shutil.rmtree(work_dir, ignore_errors=True)
    try:
        work_dir.mkdir(parents=True)
        recorder = Recorder(work_dir / JOB_RECORD_NAME, config.mcap.compression, config.mcap.chunk_size_bytes)
    except OSError as exc:
        # not even the record can start (a full disk): the journal and the bus still say why
        error = io_failure(exc, Path(task.folder), output_root) or f"internal error: {type(exc).__name__}: {exc}"
        shutil.rmtree(work_dir, ignore_errors=True)
        emit(Log("error", error))
        emit(JobFinished("failed", error, [status_message(task, "failed", finished_at=utc_now(), error=error)], None))
        return
    run = JobRun(task=task, folder=Path(task.folder), work_dir=work_dir, recorder=recorder, emit=emit)
    recorder.write(TOPIC_STATE, StateChangeRecord(job_id=task.job_id, state="queued", at=task.queued_at))
    emit(Publish(run.status("running")))
    error = None
    try:
        recorder.flush()
        for step in job_steps(run):
            started = time.perf_counter()
            run.take(step(run))
            name, seconds = step.__name__.removeprefix("step_"), time.perf_counter() - started
            run.log("info", f"step {name} finished in {seconds:.2f} s", stage=name)
            emit(StepFinished(name, seconds))
            recorder.flush()
    except FcsoError as exc:
        # a part that vanished is the symptom; a deleted folder is the cause
        error = str(exc) if run.folder.is_dir() else str(JobFolderDeleted(run.folder))
    except TimeLimitExceeded:
        error = time_limit_error(config.jobs.time_limit_seconds)
    except JobFolderDeleted as exc:
        error = str(exc)
    except Withdrawn:
        error = str(JobFolderDeleted(run.folder))
    except OSError as exc:
        error = io_failure(exc, run.folder, output_root)
        if error is None:
            error = f"internal error: {type(exc).__name__}: {exc}"
            run.log("error", traceback.format_exc())
    except Exception as exc:  # a bug or an unexpected library error: the job fails, the daemon goes on
        error = f"internal error: {type(exc).__name__}: {exc}"
        run.log("error", traceback.format_exc())
    if error is None:
        try:
            outputs = sorted([*run.files, JOB_RECORD_NAME])
            state = "done" if run.held is None else "held"
            final = run.status(state, finished_at=utc_now(), error=run.held, outputs=outputs, warnings=run.warnings)
            recorder.finish()
            _fsync_files(work_dir)
            # a held job's design messages are in its record, published when an operator approves it
            publish = [*(run.outgoing if run.held is None else []), final, *run.after_done]
        except OSError as exc:
            # the disk filled up at the very end: the job fails like any other write failure
            error = io_failure(exc, run.folder, output_root) or f"internal error: {type(exc).__name__}: {exc}"
    if error is not None:
        final = finish_failed(run, error)
        publish = [final]
    if work_dir.is_dir():
        os.replace(work_dir, final_dir)
        _fsync_dir(output_root)
    verification = verification_after_done(run) if error is None else None
    emit(
        JobFinished(
            ("done" if run.held is None else "held") if error is None else "failed",
            error,
            publish,
            None if verification is None else verification.time_limit_seconds,
        )
    )
    if verification is not None:
        verify_done_job(run, final_dir, verification)


def io_failure(exc: OSError, folder: Path, output_root: Path) -> str | None:
    """The job's error for an OS error it cannot go on after, naming the folder at fault; None for any other OS error.

    Parameters
    ----------
    exc : OSError
    folder : Path
        The job folder (its inputs).
    output_root : Path
        Where the job writes.
    """
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        written = f" ({exc.filename})" if exc.filename else ""
        return (
            f"{output_root}: no space left on device while writing the job's output{written}: "
            "the partial output was removed; free space, then change or rename the job folder to run it again"
        )
    if not folder.is_dir():
        return str(JobFolderDeleted(folder))
    return None


def finish_failed(run: JobRun, error: str) -> BusMessage:
    """End a failed job: remove its outputs, record the failure and finish the record; the ``failed`` status.

    The outputs go first, so on a full disk their space is free for the
    record's end. When even that cannot be written, the cut-off record is
    salvaged into a new one; when that fails too, nothing of the job stays
    on disk and only the journal and the bus carry the failure.
    """
    for path in run.work_dir.iterdir():
        if path.is_dir():
            shutil.rmtree(path)
        elif path.name != JOB_RECORD_NAME:
            path.unlink()
    try:
        run.log("error", error)
        final = run.status("failed", finished_at=utc_now(), error=error)
        run.recorder.finish()
        _fsync_files(run.work_dir)
        return final
    except Exception:  # the record's writer may be broken by the write that failed: salvage what it holds
        run.recorder.close_unfinished()
    final = run.status("failed", finished_at=utc_now(), error=error, record=False)
    try:
        record_failure(
            run.work_dir, run.task.job_id, error, final, utc_now(), run.task.config.mcap, run.task.config.ros2
        )
        _fsync_files(run.work_dir)
    except OSError:
        shutil.rmtree(run.work_dir, ignore_errors=True)
        run.emit(
            Log(
                "error",
                "no space even for the job's record: nothing of the job is kept on disk",
                {"path": str(run.work_dir)},
            )
        )
    return final


def _fsync_files(folder: Path) -> None:
    """Push every file of ``folder`` and its set folders to disk."""
    for path in folder.rglob("*"):
        if path.is_dir():
            continue
        with open(path, "rb") as stream:
            os.fsync(stream.fileno())


def _fsync_dir(path: Path) -> None:
    """Make a rename in ``path`` durable."""
    descriptor = os.open(path, os.O_RDONLY)
    try:
        os.fsync(descriptor)
    finally:
        os.close(descriptor)
