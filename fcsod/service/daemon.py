"""The daemon's main loop: watch, queue, run jobs in worker processes, publish, journal.

One process owns the zenoh session, the journal and the watcher; jobs run
in worker processes (``concurrency`` of them at most, each for one job, so a
crashing job cannot take the daemon down), forked by multiprocessing's fork
server: a fresh interpreter, not a fork of the daemon and its bus threads,
that imported the job's code once. One worker is started ahead of need.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import shutil
import signal
import time
from dataclasses import dataclass, field
from functools import partial
from multiprocessing.connection import Connection, wait
from pathlib import Path

from .. import __version__
from ..bus.messages import BusMessage, BusRecord, StatusMessage, VerificationMessage, utc_now
from ..bus.pki import link_weaknesses
from ..bus.ros2 import Ros2Node, node_fqn
from ..bus.session import Bus, session_config
from ..bus.signing import daemon_signer, signing_key_path
from ..config import DaemonConfig
from ..job.events import (
    JobFinished,
    Log,
    Publish,
    Scene,
    StepFinished,
    VerificationFinished,
    VerificationStarted,
    WorkerBroken,
    WorkerEvent,
    WorkerReady,
)
from ..job.inputs import hash_inputs, job_id, job_inputs
from ..job.process import WORKER_PRELOAD, worker_main
from ..job.task import (
    SIGNAL_TIME_LIMIT,
    SIGNAL_WITHDRAWN,
    JobFolderDeleted,
    JobTask,
    VerificationTask,
    time_limit_error,
    unfinished_verification_message,
)
from ..record.failure import record_failure
from ..record.recorder import JOB_RECORD_NAME, TOPIC_BUS, TOPIC_STATE, read_record
from ..storage import lock_state_dir
from .journal import JobRow, Journal, JournalCorrupt, journal_problem, stored_message, stored_messages
from .metrics import DaemonMetrics
from .requests import CANCELLED_ERROR, OperatorRequests, withheld
from .systemd import notify, watchdog_interval
from .watcher import FolderWatcher, Readiness, signature_of

log = logging.getLogger("fcsod")

#: Longest wait of the main loop for an event, s.
TICK_S = 0.2


@dataclass
class WorkerSlot:
    """A worker process and the job it runs, if any."""

    process: multiprocessing.process.BaseProcess
    connection: Connection
    ready: bool = False
    job: JobRow | None = None
    started: float = 0.0
    #: why and when the worker was told to stop: the job's error if it then dies
    stop_error: str | None = None
    stop_signalled_at: float | None = None
    finished: bool = False
    #: the job is done and its worker verifies its design until this (monotonic s); None: no verification runs
    verify_deadline: float | None = None
    #: that verification's time limit, s
    verify_limit_s: float = 0.0
    open: bool = True
    events: list = field(default_factory=list)


def _start_verification_clock(slot: WorkerSlot, limit_s: float) -> None:
    """The slot's worker verifies from now, for at most ``limit_s``."""
    slot.verify_deadline, slot.verify_limit_s = time.monotonic() + limit_s, limit_s


class Daemon(OperatorRequests):
    """``fcsod run``.

    Parameters
    ----------
    config : DaemonConfig
        Validated settings.
    """

    def __init__(self, config: DaemonConfig):
        self.config = config
        self.output_root = config.output.root
        self.state_dir = config.state.dir
        self.journal_path = self.state_dir / "journal.sqlite3"
        self.stopping = False
        self.slots: list[WorkerSlot] = []
        self.known: dict[Path, tuple] = {}
        #: done jobs whose verification a crash or a stop cut off: run again first
        self.unverified: list[str] = []
        #: why job workers cannot start (they died importing the job's code); None while they can
        self.workers_broken: str | None = None
        # workers fork from a server that imported the job's code once: a job starts at once instead of after a new
        # interpreter's imports (about 3 s on a 2-core host, longer than a job that reuses a finger)
        self._context = multiprocessing.get_context("forkserver")
        self._context.set_forkserver_preload(list(WORKER_PRELOAD))
        # only this process holds the write end (never written): the workers' read ends end when it dies
        self._life_line, self._life_line_writer = self._context.Pipe(duplex=False)
        self._lock_file = None
        self.metrics = DaemonMetrics(self.journal_path)
        self.foxglove = None

    # ---------------------------------------------------------------- lifecycle

    def run(self) -> int:
        """Run until SIGTERM or SIGINT; returns the process exit code."""
        self.state_dir.mkdir(parents=True, exist_ok=True)
        self.output_root.mkdir(parents=True, exist_ok=True)
        self._lock_file = lock_state_dir(self.state_dir)
        problem = journal_problem(self.journal_path)
        if problem is not None:
            raise JournalCorrupt(
                f"{self.journal_path}: the journal is corrupt ({problem}); fcsod does not start on it. "
                "Run `fcsod journal rebuild --config FILE` to rebuild it from the job records (job.mcap) in the "
                "output folder"
            )
        self.journal = Journal(self.journal_path)
        self._clean_work_dirs()
        for job in self.journal.requeue_running():
            log.info("re-queued job left running by the previous run", extra={"job_id": job})
        for row in self.journal.unfinished_verifications():
            self.unverified.append(row.job_id)
            log.info("re-queued the verification left running by the previous run", extra={"job_id": row.job_id})
        signal.signal(signal.SIGTERM, self._on_stop_signal)
        signal.signal(signal.SIGINT, self._on_stop_signal)
        signer, created = daemon_signer(self.config)
        if created:
            log.info(
                "created the message-signing key: give signing.pub to the cell controllers",
                extra={"path": str(signing_key_path(self.config))},
            )
        for weakness in link_weaknesses(session_config(self.config.zenoh)):
            log.warning(f"insecure bus: {weakness}")
        self.signer = signer
        self.bus = Bus(self.config.bus, self.config.zenoh, partial(stored_messages, self.journal_path))
        self.ros2 = Ros2Node(self.bus.session, self.config.ros2) if self.config.ros2.enabled else None
        if self.ros2 is not None:
            log.info(
                "ROS 2 node " + node_fqn(self.config.ros2),
                extra={"ros2_key_exprs": [p.key_expr for p in self.ros2.publishers.values()]},
            )
        watch = self.config.watch
        self.watcher = FolderWatcher(watch.roots, watch.polling, watch.poll_interval_seconds)
        self.readiness = Readiness(watch.settle_seconds)
        self.watcher.start()
        if self.config.metrics.enabled:
            self.metrics.serve(self.config.metrics)
            log.info("metrics endpoint", extra={"url": f"http://{self.config.metrics.listen}/metrics"})
        if self.config.foxglove.enabled:
            from .foxglove_live import FoxgloveLive

            self.foxglove = FoxgloveLive(self.config.foxglove)
            log.info("Foxglove live server", extra={"url": f"ws://{self.config.foxglove.listen}"})
        self._rescan()
        self._fill_workers()
        log.info(
            "fcsod started",
            extra={
                "version": __version__,
                "roots": [str(r) for r in watch.roots],
                "output": str(self.output_root),
                "observer": "polling" if watch.polling else "inotify",
                "key_prefix": f"{self.config.bus.prefix}/{self.config.bus.cell}",
                "signing_key_id": signer.key_id,
            },
        )
        notify("READY=1")
        try:
            self._loop()
        finally:
            self._shutdown()
        return 0

    def _on_stop_signal(self, signum, frame) -> None:
        self.stopping = True

    def _clean_work_dirs(self) -> None:
        """Remove work folders of runs cut off by a crash: a partial result is never left behind."""
        for path in self.output_root.glob(".tmp-*"):
            shutil.rmtree(path, ignore_errors=True)
            log.info("removed partial output of an interrupted run", extra={"path": str(path)})

    def _shutdown(self) -> None:
        """Stop watching, re-queue running jobs (their workers are killed), close the bus and the journal."""
        notify("STOPPING=1")
        self.watcher.stop()
        for slot in self.slots:
            if slot.process.is_alive():
                slot.process.kill()
            slot.process.join(timeout=10)
            if slot.job is not None and (not slot.finished or slot.verify_deadline is not None):
                self._drain(slot)
            if slot.verify_deadline is not None:
                log.info(
                    "stopped a verification; it will run again at the next start", extra={"job_id": slot.job.job_id}
                )
            if slot.job is not None and not slot.finished:
                shutil.rmtree(self.output_root / f".tmp-{slot.job.job_id}", ignore_errors=True)
                self.journal.requeue_running()
                log.info(
                    "stopped a running job; it will run again at the next start", extra={"job_id": slot.job.job_id}
                )
        if self.ros2 is not None:
            self.ros2.close()
        self.bus.close()
        self.journal.close()
        self.metrics.close()
        if self.foxglove is not None:
            self.foxglove.close()
        log.info("fcsod stopped")
        if self._lock_file is not None:
            self._lock_file.close()

    # ---------------------------------------------------------------- loop

    def _loop(self) -> None:
        watch = self.config.watch
        next_rescan = time.monotonic() + watch.rescan_seconds
        ping_interval = watchdog_interval()
        next_ping = time.monotonic()
        while not self.stopping:
            waitables = [s.connection for s in self.slots if s.open] + [s.process.sentinel for s in self.slots]
            wait(waitables, timeout=TICK_S)
            for slot in list(self.slots):
                self.collect(slot)
            for folder in self.watcher.take_changed():
                self.readiness.touch(folder)
            now = time.monotonic()
            if now >= next_rescan or self.watcher.rescan_requested.is_set():
                self.watcher.rescan_requested.clear()
                self._rescan()
                next_rescan = now + watch.rescan_seconds
            for ready in self.readiness.poll():
                self._enqueue(ready.folder, ready.inputs, ready.signature)
            self._stop_overdue_and_withdrawn_jobs()
            self.handle_requests()
            self._dispatch()
            self._fill_workers()
            if ping_interval is not None and time.monotonic() >= next_ping:
                notify("WATCHDOG=1")
                next_ping = time.monotonic() + ping_interval

    def _rescan(self) -> None:
        """Reconsider every job folder whose inputs differ from when it was last queued."""
        for folder in self.watcher.all_folders():
            if self.known.get(folder) != signature_of(folder, job_inputs(folder)):
                self.readiness.touch(folder)

    # ---------------------------------------------------------------- queue

    def _enqueue(self, folder: Path, inputs, signature: tuple) -> None:
        if self.known.get(folder) == signature:
            # touched, not changed: same inputs as when it was last queued
            return
        hashed = hash_inputs(folder, inputs, self.config.limits.max_file_bytes)
        identity = job_id(folder.name, hashed)
        self.known[folder] = signature
        if not self.journal.add(identity, str(folder), utc_now()):
            row = self.journal.get(identity)
            log.info(
                "job already known: not run again",
                extra={"job_id": identity, "folder": str(folder), "state": row.state},
            )
            return
        row = self.journal.get(identity)
        log.info("job queued", extra={"job_id": identity, "folder": str(folder), "inputs": len(hashed)})
        self.publish(self.status(row))

    def _dispatch(self) -> None:
        if self.workers_broken is not None:
            for row in self.journal.jobs("queued"):
                self.fail_dead_job(row, self.workers_broken)
            return
        idle = [s for s in self.slots if s.ready and s.job is None and s.process.is_alive()]
        free = self.config.jobs.concurrency - sum(1 for s in self.slots if s.job is not None)
        if not idle or free <= 0:
            return
        while idle and free > 0 and self.unverified:
            self._dispatch_verification(idle.pop(0), self.unverified.pop(0))
            free -= 1
        for row in self.journal.jobs("queued"):
            if not idle or free <= 0:
                break
            if (self.output_root / row.job_id / JOB_RECORD_NAME).is_file():
                self._adopt(row)
                continue
            row = self.journal.mark_running(row.job_id, utc_now())
            slot = idle.pop(0)
            slot.job, slot.started = row, time.monotonic()
            task = JobTask(row.job_id, row.folder, row.attempt, row.queued_at, row.started_at, self.config)
            slot.connection.send(task)
            free -= 1
            log.info(
                "job started", extra={"job_id": row.job_id, "attempt": row.attempt, "worker_pid": slot.process.pid}
            )

    def _dispatch_verification(self, slot: WorkerSlot, job_id: str) -> None:
        """Hand a done job's cut-off verification to a worker (it runs again from the job's output folder)."""
        verification = self.journal.restart_verification(job_id, utc_now())
        slot.job, slot.started, slot.finished = self.journal.get(job_id), time.monotonic(), True
        _start_verification_clock(slot, self.config.verify.time_limit_seconds)
        slot.connection.send(VerificationTask(job_id, slot.job.folder, self.config))
        log.info(
            "verification started again",
            extra={"job_id": job_id, "attempt": verification.attempt, "worker_pid": slot.process.pid},
        )

    def _adopt(self, row: JobRow) -> None:
        """Finish the journal of a job whose output folder is complete (the daemon stopped between rename and
        journal).
        """
        content = read_record(self.output_root / row.job_id / JOB_RECORD_NAME)
        states = content.of(TOPIC_STATE)
        final = states[-1] if states else {"state": "failed", "error": "record holds no state"}
        state = final["state"] if final["state"] in ("done", "failed", "held") else "failed"
        self.journal.mark_running(row.job_id, row.started_at or utc_now())
        self.journal.mark_finished(row.job_id, state, final.get("at") or utc_now(), final.get("error"))
        log.info(
            "job output already complete: journal updated from its record", extra={"job_id": row.job_id, "state": state}
        )
        recorded = [BusMessage.from_record(BusRecord.model_validate(body)) for body in content.of(TOPIC_BUS)]
        for message in recorded if state != "held" else [m for m in recorded if not withheld(m)]:
            self.publish(message)

    # ---------------------------------------------------------------- workers

    def _fill_workers(self) -> None:
        """Keep one idle worker process beyond ``concurrency``, started ahead of the job that will use it.

        A worker runs one job and exits (a job cannot leave anything behind
        for the next); the spare one has done its imports by the time it is needed.
        """
        while not self.stopping and self.workers_broken is None and len(self.slots) < self.config.jobs.concurrency + 1:
            ours, theirs = self._context.Pipe(duplex=True)
            process = self._context.Process(target=worker_main, args=(theirs, self._life_line), name="fcsod-worker")
            try:
                process.start()
            except (OSError, EOFError) as exc:
                # the fork server died importing the job's code with more than an ImportError (those the worker
                # reports itself): its traceback is on stderr
                ours.close()
                theirs.close()
                self._workers_cannot_start(f"the workers' fork server failed: {type(exc).__name__}: {exc}")
                return
            theirs.close()
            self.slots.append(WorkerSlot(process, ours))

    def _workers_cannot_start(self, error: str) -> None:
        """A worker died importing the job's code: no more are started, and queued jobs fail with why (not retried
        forever), until fcsod is restarted with a working installation.
        """
        if self.workers_broken is not None:
            return
        self.workers_broken = (
            f"job workers cannot start ({error}): fix the installation, restart fcsod, then retry the job"
        )
        log.error(self.workers_broken)

    def collect(self, slot: WorkerSlot) -> None:
        """Handle what the worker sent; remove it if it exited."""
        self._drain(slot)
        if not slot.process.is_alive():
            if slot.open:
                # what a dead worker sent is drained above; processes it forked may
                # still hold its end of the pipe open, so the end of file may never come
                slot.open = False
                slot.connection.close()
            self._reap(slot)

    def _drain(self, slot: WorkerSlot) -> None:
        """Handle every event the worker has sent."""
        while slot.open:
            try:
                if not slot.connection.poll():
                    return
                event = slot.connection.recv()
            except (EOFError, OSError):
                slot.open = False
                slot.connection.close()
                return
            self._handle(slot, event)

    def _handle(self, slot: WorkerSlot, event: WorkerEvent) -> None:
        """Act on one event of a worker."""
        match event:
            case WorkerReady():
                slot.ready = True
            case WorkerBroken(error):
                self._workers_cannot_start(error)
            case Log(level, message, fields):
                log.log(logging.getLevelName(level.upper()), message, extra={"job_id": slot.job.job_id, **fields})
            case Publish(message):
                self.publish(message)
            case Scene(topic, data, log_time_ns):
                if self.foxglove is not None:
                    self.foxglove.log_scene(topic, data, log_time_ns)
            case StepFinished(name, seconds):
                self.metrics.stage_seconds.labels(name).observe(seconds)
            case JobFinished():
                self._finished(slot, event)
            case VerificationStarted(time_limit_seconds):
                _start_verification_clock(slot, time_limit_seconds)
            case VerificationFinished(state, error, messages):
                self._verified(slot, state, error, messages)

    def _finished(self, slot: WorkerSlot, event: JobFinished) -> None:
        """The job ended: journal its state, then publish its messages."""
        state, error, messages, verify_limit_s = event.state, event.error, event.messages, event.verify_limit_seconds
        status = next(StatusMessage.model_validate_json(m.payload) for m in reversed(messages) if m.topic == "status")
        # a verification that follows is journalled with the done state: a crash during it runs it again
        row = self.journal.mark_finished(
            slot.job.job_id, state, status.finished_at, error, verifying=verify_limit_s is not None
        )
        self.metrics.jobs_finished.labels("cancelled" if error == CANCELLED_ERROR else state).inc()
        self.metrics.job_seconds.labels(state).observe(time.monotonic() - slot.started)
        if state == "done":
            self.metrics.last_success.set_to_current_time()
        slot.finished = True
        if verify_limit_s is not None:
            _start_verification_clock(slot, verify_limit_s)
        extra = {"job_id": row.job_id, "state": state, "seconds": round(time.monotonic() - slot.started, 3)}
        if state == "held":
            log.warning(f"job held: {error}", extra=extra)
        elif error:
            log.error(f"job failed: {error}", extra=extra)
        else:
            log.info("job done", extra={**extra, "output": str(self.output_root / row.job_id)})
        for message in messages:
            self.publish(message)

    def _verified(self, slot: WorkerSlot, state: str, error: str | None, messages: list[BusMessage]) -> None:
        """A done job's verification ended: journal its state with its messages, then publish them."""
        signed = [self.signer.sign(m) for m in messages]
        self.journal.finish_verification(
            slot.job.job_id, state, utc_now(), error, [stored_message(m, self.output_root) for m in signed]
        )
        slot.verify_deadline = None
        log.log(
            logging.INFO if state == "done" else logging.WARNING,
            f"verification {state}" + (f": {error}" if error else ""),
            extra={"job_id": slot.job.job_id, "state": state},
        )
        for message in signed:
            self._count_verification(message)
            self.bus.publish(message)
            if self.ros2 is not None:
                self.ros2.publish(message)

    def _reap(self, slot: WorkerSlot) -> None:
        """Remove an exited worker; fail its job if it died before reporting (or its verification)."""
        slot.process.join()
        self.slots.remove(slot)
        if slot.verify_deadline is not None and not self.stopping:
            code = slot.process.exitcode
            error = slot.stop_error or f"worker process died while verifying the design (exit code {code})"
            message = unfinished_verification_message(self.config.bus, slot.job.job_id, "failed", error, None)
            self._verified(slot, "failed", error, [message])
            return
        if slot.job is None or slot.finished:
            if slot.job is None and not self.stopping:
                log.error("worker process exited before taking a job", extra={"exit_code": slot.process.exitcode})
            return
        if slot.stop_error is not None:
            error = slot.stop_error
        else:
            code = slot.process.exitcode
            how = (
                f"killed by signal {signal.Signals(-code).name}"
                if code is not None and code < 0
                else f"exit code {code}"
            )
            error = f"worker process died while running the job ({how})"
        self.fail_dead_job(slot.job, error)

    def fail_dead_job(self, row: JobRow, error: str) -> None:
        """Record the failure of a job whose worker died: salvage its record, finish it, publish ``failed``."""
        final_dir = self.output_root / row.job_id
        if (final_dir / JOB_RECORD_NAME).is_file():
            self._adopt(row)
            return
        work_dir = self.output_root / f".tmp-{row.job_id}"
        finished_at = utc_now()
        row = self.journal.mark_finished(row.job_id, "failed", finished_at, error)
        self.metrics.jobs_finished.labels("cancelled" if error == CANCELLED_ERROR else "failed").inc()
        status = self.status(row)
        try:
            work_dir.mkdir(parents=True, exist_ok=True)
            for path in work_dir.iterdir():
                if path.name != JOB_RECORD_NAME:
                    shutil.rmtree(path) if path.is_dir() else path.unlink()
            record_failure(work_dir, row.job_id, error, status, finished_at, self.config.mcap, self.config.ros2)
            os.replace(work_dir, final_dir)
        except OSError as exc:
            # e.g. the output disk is full: the journal and the bus still say why the job failed
            shutil.rmtree(work_dir, ignore_errors=True)
            log.error(
                f"cannot write the failed job's record: {exc}", extra={"job_id": row.job_id, "path": str(work_dir)}
            )
        log.error(f"job failed: {error}", extra={"job_id": row.job_id, "state": "failed"})
        self.publish(status)

    def _stop_overdue_and_withdrawn_jobs(self) -> None:
        """Stop a job over its time limit or whose folder was deleted (the print job withdrawn).

        Its worker is killed when it has not stopped after the grace time.
        """
        jobs = self.config.jobs
        now = time.monotonic()
        for slot in self.slots:
            if slot.job is None or not slot.process.is_alive() or (slot.finished and slot.verify_deadline is None):
                continue
            if slot.stop_signalled_at is None:
                if slot.finished:
                    if now <= slot.verify_deadline:
                        continue
                    log.warning("verification over its time limit: stopping it", extra={"job_id": slot.job.job_id})
                    # the worker publishes the failure; this is the error if it has to be killed
                    slot.stop_error = time_limit_error(slot.verify_limit_s, "verification", "verify.time_limit_seconds")
                    stop_signal = SIGNAL_TIME_LIMIT
                elif now - slot.started > jobs.time_limit_seconds:
                    log.warning("job over its time limit: stopping it", extra={"job_id": slot.job.job_id})
                    slot.stop_error, stop_signal = time_limit_error(jobs.time_limit_seconds), SIGNAL_TIME_LIMIT
                elif not Path(slot.job.folder).is_dir():
                    log.warning("job folder deleted: withdrawing its job", extra={"job_id": slot.job.job_id})
                    slot.stop_error, stop_signal = str(JobFolderDeleted(Path(slot.job.folder))), SIGNAL_WITHDRAWN
                else:
                    continue
                os.kill(slot.process.pid, stop_signal)
                slot.stop_signalled_at = now
            elif now - slot.stop_signalled_at > jobs.stop_grace_seconds:
                slot.process.kill()

    # ---------------------------------------------------------------- bus

    def status(self, row: JobRow) -> BusMessage:
        """The status message of a job as the journal has it."""
        body = StatusMessage(
            job_id=row.job_id,
            state=row.state,
            folder=row.folder,
            attempt=max(row.attempt, 1),
            queued_at=row.queued_at,
            started_at=row.started_at,
            finished_at=row.finished_at,
            error=row.error,
        )
        return BusMessage.json_body(self.config.bus.prefix, self.config.bus.cell, "status", body)

    def _count_verification(self, message: BusMessage) -> None:
        """Count a verification's result, wherever it ran (the design step's choice, after the job, again after a
        crash): a verification message that finished (``state`` done)."""
        if message.topic.partition("/")[0] != "verification":
            return
        body = VerificationMessage.model_validate_json(message.payload)
        if body.state == "done":
            self.metrics.verified(body.passed)

    def publish(self, message: BusMessage) -> None:
        """Sign the message, keep it for the queryable, count a verification, then publish it."""
        self._count_verification(message)
        message = self.signer.sign(message)
        self.journal.store_message(stored_message(message, self.output_root))
        transports = [("zenoh", self.bus), ("ros2", self.ros2), ("foxglove", self.foxglove)]
        for transport, publisher in transports:
            if publisher is None:
                continue
            try:
                publisher.publish(message)
            except Exception as exc:  # the journal keeps the message for the queryable; the daemon goes on
                self.metrics.publish_failures.labels(transport).inc()
                log.error(
                    f"cannot publish on {transport}: {type(exc).__name__}: {exc}",
                    extra={"job_id": message.job_id, "key": message.key_expr},
                )
