"""A job as the worker runs it: the task the daemon hands over, the state its steps share, its status message.

The worker (:mod:`fcsod.job.process`) checks the job's inputs, runs
:func:`fcso.design_sets`, writes the results into
``<output_root>/.tmp-<job_id>/`` and records ``job.mcap`` as it goes (flushed
after every stage), then renames the folder to ``<output_root>/<job_id>/``.
A failed job's folder holds ``job.mcap`` only. The worker never touches
zenoh: the messages to publish go back to the daemon over a pipe, after they
are in the record. The job runs as a list of steps (:mod:`fcsod.job.steps`);
each takes the :class:`JobRun`, records what it made and returns it, frozen, for the steps after it.
"""

from __future__ import annotations

import hashlib
import signal
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import fcso
from fcso import DesignConfig, DesignResult
from fcso.sets import SetsResult

from ..bus.messages import (
    BusMessage,
    InputFile,
    LogRecord,
    OutputFilesRecord,
    StateChangeRecord,
    StatusMessage,
    VerificationMessage,
    utc_now,
)
from ..bus.ros2 import record_ros2
from ..config import DaemonConfig, JobManifest, VerifySettings
from ..plate.build3mf import Build
from ..plate.models import BuildConfig
from ..record.recorder import TOPIC_BUS, TOPIC_LOG, TOPIC_OUTPUTS, TOPIC_SCENE, TOPIC_STATE, TOPIC_TRANSFORMS, Recorder
from .events import Emit, Log, Scene
from .inputs import PartInput

if TYPE_CHECKING:
    from fcso.sim.report import VerificationReport
    from fcso.sim.verify import DesignUnderTest

#: Shortest interval between two progress lines of the same stage, s.
PROGRESS_INTERVAL_S = 1.0

#: The placed build in every done job's output folder.
BUILD_NAME = "build.3mf"

#: A held job's build with its finger placed, beside ``build.3mf`` (the parts alone): ``fcsod approve`` puts it in
#: ``build.3mf``'s place.
HELD_BUILD_NAME = "build.held.3mf"

#: Number of the finger set of a job served by one finger, in ``build.3mf``.
FINGER_SET = 1


class JobFolderDeleted(Exception):
    """The job folder disappeared while its job ran: the print job was withdrawn."""

    def __init__(self, folder: Path):
        super().__init__(
            f"{folder}: the job folder was deleted while its job ran: the job is withdrawn, nothing of it is published"
        )


class TimeLimitExceeded(BaseException):
    """Raised in the worker when the daemon signals that the job ran out of time.

    A BaseException so that libraries catching ``Exception`` cannot swallow it.
    """


class Withdrawn(BaseException):
    """Raised in the worker when the daemon signals that the job's folder was deleted (a BaseException, as above)."""


#: The signals by which the daemon stops a running job: out of time, or withdrawn.
SIGNAL_TIME_LIMIT = signal.SIGUSR1
SIGNAL_WITHDRAWN = signal.SIGUSR2


def time_limit_error(limit_seconds: float, stage: str = "job", setting: str = "jobs.time_limit_seconds") -> str:
    """The error of a job (or its verification, ``stage``) stopped when ``setting``, ``limit_seconds``, ran out."""
    return f"time limit exceeded: the {stage} ran longer than {setting} ({limit_seconds:g} s)"


@dataclass
class JobTask:
    """What the daemon hands a worker.

    Attributes
    ----------
    job_id, folder : str
        The job and its watched folder.
    attempt : int
        Run number (more than 1 after a restart re-queued the job).
    queued_at, started_at : str
        UTC ISO 8601 times from the journal.
    config : DaemonConfig
        The daemon's settings.
    """

    job_id: str
    folder: str
    attempt: int
    queued_at: str
    started_at: str
    config: DaemonConfig


@dataclass
class VerificationTask:
    """What the daemon hands a worker to run a done job's verification again (a crash or a stop cut it off).

    Attributes
    ----------
    job_id, folder : str
        The job and its watched folder (its ``job.toml`` gives the job's ``[verify]``).
    config : DaemonConfig
        The daemon's settings.
    """

    job_id: str
    folder: str
    config: DaemonConfig


def unfinished_verification_message(bus, job_id: str, state: str, error: str, finger_set: int | None) -> BusMessage:
    """The message of a verification that failed or was skipped, on ``.../verification`` (or
    ``.../verification/<set>``).

    Parameters
    ----------
    bus : BusConfig
    job_id : str
    state : {'failed', 'skipped'}
    error : str
        Why.
    finger_set : int or None
        The finger set of a job of several.
    """
    body = VerificationMessage(
        job_id=job_id,
        state=state,
        error=error,
        passed=False,
        file=None,
        finger_set=finger_set,
        scenarios=[],
        warnings=[],
    )
    topic = "verification" if finger_set is None else f"verification/{finger_set}"
    return BusMessage.json_body(bus.prefix, bus.cell, topic, body)


@dataclass(frozen=True)
class JobInputs:
    """What :func:`~fcsod.job.steps.step_inputs` makes of the job folder."""

    #: every input file with its size and content hash
    files: list[InputFile]
    manifest: JobManifest
    #: ``job.toml`` as written, None without one
    manifest_text: str | None
    #: the job's fcso settings: the daemon's, the manifest's overrides, the daemon's [compute] and the job's [verify]
    settings: DesignConfig
    #: the job's [verify] (its manifest's, else the daemon's)
    verify_settings: VerifySettings
    build_settings: BuildConfig
    #: the part files, checked against the limits
    parts: list[PartInput]


@dataclass(frozen=True)
class LoadedParts:
    """What :func:`~fcsod.job.steps.step_load` makes of the part files."""

    #: every distinct part, loaded and validated, with its pieces to pick
    parts: list[fcso.Part]
    #: the job's build: the part items, placed by the job or to pack (the finger copies join it when placed)
    build: Build


@dataclass(frozen=True)
class Reuse:
    """What :func:`~fcsod.job.reuse.step_reuse` found: the finger library serves every part of the job."""

    #: part name -> how the library serves it (:class:`~fcsod.job.fingers.ServedPart`)
    served: dict


@dataclass(frozen=True)
class DesignedSets:
    """What :func:`~fcsod.job.steps.step_design` made."""

    sets: SetsResult
    #: what the design warns of (parts left out, sets near zero quality), for the job's done status
    warnings: tuple[str, ...]


@dataclass(frozen=True)
class SetVerified:
    """One finger set's delivered design, verified before it is placed."""

    verification: VerificationReport
    #: the delivered design's simulation inputs (the report's pictures)
    design: DesignUnderTest
    #: the verified candidates' ranking for the report, HTML ('' when the design's own choice alone was verified)
    ranking_html: str


@dataclass(frozen=True)
class Verified:
    """What :func:`~fcsod.job.verification.choose_by_verification` made: every finger set's delivered design,
    verified (one set or several alike)."""

    #: the finger sets with the delivered candidates
    sets: SetsResult
    #: per finger set, in set order
    fingers: tuple[SetVerified, ...]
    #: why fingers miss the delivery policy ([verify] deliver): the job ends held (fcsod approve / reject);
    #: None: they are delivered
    held: str | None
    #: for the job's done status
    warnings: tuple[str, ...]


@dataclass(frozen=True)
class RecordedDesign:
    """What :func:`~fcsod.job.steps.step_record_design` made: every finger set's meshes (STL) by output path."""

    files: dict[str, bytes]


@dataclass(frozen=True)
class Placed:
    """What :func:`~fcsod.job.steps.step_placement` made."""

    #: the finger sets whose reports hold the placement section
    sets: SetsResult
    #: ``build.3mf`` (and a held job's ``build.held.3mf``)
    files: dict[str, bytes]
    #: the placement message, published after the design's
    message: BusMessage
    #: fingers that did not fit, for the job's done status
    warnings: tuple[str, ...]


@dataclass(frozen=True)
class Outputs:
    """What :func:`~fcsod.job.steps.step_outputs` (or :func:`~fcsod.job.reuse.step_reused_outputs`) made: the job's
    output files, written and recorded, and its messages, recorded."""

    #: every output file by path in the output folder
    files: dict[str, bytes]
    #: published with the done status (a held job's when an operator approves it)
    outgoing: tuple[BusMessage, ...]
    #: published after the done status (the verification of the delivered candidate)
    after_done: tuple[BusMessage, ...] = ()
    #: for the job's done status
    warnings: tuple[str, ...] = ()


#: What a step may return: the runner keeps it in the :class:`JobRun` for the steps after it.
StepResult = JobInputs | LoadedParts | Reuse | DesignedSets | Verified | RecordedDesign | Placed | Outputs | None


@dataclass
class JobRun:
    """A running job: what its steps share, and what each step made.

    Every step returns what it made (:data:`StepResult`, frozen) and the
    runner keeps it (:meth:`take`); the steps after it read it by name
    (``run.settings``, ``run.loaded``, ``run.sets``, ...), which is empty
    (None, no items) before the step that makes it has run. The types say
    the order: a step reads only what the steps before it returned.
    """

    task: JobTask
    folder: Path
    work_dir: Path
    recorder: Recorder
    emit: Emit
    job_inputs: JobInputs | None = None
    loaded_parts: LoadedParts | None = None
    reused: Reuse | None = None
    designed: DesignedSets | None = None
    verified: Verified | None = None
    recorded: RecordedDesign | None = None
    placed: Placed | None = None
    outputs: Outputs | None = None

    def take(self, made: StepResult) -> None:
        """Keep what a step made for the steps after it."""
        match made:
            case JobInputs():
                self.job_inputs = made
            case LoadedParts():
                self.loaded_parts = made
            case Reuse():
                self.reused = made
            case DesignedSets():
                self.designed = made
            case Verified():
                self.verified = made
            case RecordedDesign():
                self.recorded = made
            case Placed():
                self.placed = made
            case Outputs():
                self.outputs = made

    @property
    def manifest(self) -> JobManifest | None:
        return self.job_inputs.manifest if self.job_inputs is not None else None

    @property
    def settings(self) -> DesignConfig | None:
        return self.job_inputs.settings if self.job_inputs is not None else None

    @property
    def verify_settings(self) -> VerifySettings | None:
        return self.job_inputs.verify_settings if self.job_inputs is not None else None

    @property
    def build_settings(self) -> BuildConfig | None:
        return self.job_inputs.build_settings if self.job_inputs is not None else None

    @property
    def loaded(self) -> list[fcso.Part]:
        return self.loaded_parts.parts if self.loaded_parts is not None else []

    @property
    def build(self) -> Build:
        return self.loaded_parts.build if self.loaded_parts is not None else Build()

    @property
    def reuse(self) -> dict | None:
        """Part name -> how the finger library serves it, when it serves the whole job; else None."""
        return self.reused.served if self.reused is not None else None

    @property
    def sets(self) -> SetsResult | None:
        """The finger sets as the latest step left them: placed, else verified, else designed."""
        return next((made.sets for made in (self.placed, self.verified, self.designed) if made is not None), None)

    @property
    def result(self) -> DesignResult:
        """The first finger set's design: the job's design when one set serves it."""
        return self.sets.designs[0]

    @property
    def held(self) -> str | None:
        """Why the finger waits for an operator ([verify] deliver); None when it is delivered."""
        return self.verified.held if self.verified is not None else None

    @property
    def files(self) -> dict[str, bytes]:
        """Every output file, once the outputs are written."""
        return self.outputs.files if self.outputs is not None else {}

    @property
    def outgoing(self) -> tuple[BusMessage, ...]:
        return self.outputs.outgoing if self.outputs is not None else ()

    @property
    def after_done(self) -> tuple[BusMessage, ...]:
        return self.outputs.after_done if self.outputs is not None else ()

    @property
    def warnings(self) -> list[str]:
        """What the steps warn of, in their order, for the job's done status."""
        made = (self.designed, self.verified, self.placed, self.outputs)
        return [warning for step in made if step is not None for warning in step.warnings]

    def write_files(self, files: dict[str, bytes]) -> None:
        """Write output ``files`` (path -> content) into the work folder (:meth:`record_files` then records their
        hashes)."""
        for name, data in files.items():
            path = self.work_dir / name
            try:
                path.parent.mkdir(exist_ok=True)
                path.write_bytes(data)
            except OSError as exc:
                # a failed write() does not say which file it was writing
                raise OSError(exc.errno, exc.strerror, str(path)) from exc

    def record_files(self, files: dict[str, bytes]) -> None:
        """Record the hashes of every output file (``files``: path -> content) in ``job.mcap``."""
        self.recorder.write(
            TOPIC_OUTPUTS,
            OutputFilesRecord(
                job_id=self.task.job_id,
                files=[
                    InputFile(path=n, size_bytes=len(d), sha256=hashlib.sha256(d).hexdigest()) for n, d in files.items()
                ],
            ),
        )

    def log(self, level: str, message: str, **fields) -> None:
        """Record a log line and send it to the daemon's log."""
        self.recorder.write(TOPIC_LOG, LogRecord(level=level, message=message, **fields))
        self.emit(Log(level, message, fields))

    def scene(self, update, transforms=None) -> None:
        """Record a Foxglove ``SceneUpdate`` (foxglove-sdk's) on ``/scene``, after the ``FrameTransforms`` it is drawn
        in on ``/tf`` if given, and send them to the daemon's live server.
        """
        now = time.time_ns()
        if transforms is not None:
            self.emit(Scene(TOPIC_TRANSFORMS, self.recorder.write_foxglove(TOPIC_TRANSFORMS, transforms, now), now))
        self.emit(Scene(TOPIC_SCENE, self.recorder.write_foxglove(TOPIC_SCENE, update, now), now))

    def record_published(self, message: BusMessage) -> None:
        """Record a message to publish on the bus channel and, in its ROS 2 form, on the ROS 2 channels."""
        self.recorder.write(TOPIC_BUS, message.record())
        record_ros2(self.recorder, message, self.task.config.ros2)

    def status(
        self,
        state: str,
        finished_at: str | None = None,
        error: str | None = None,
        outputs: list[str] | None = None,
        warnings: list[str] | None = None,
        record: bool = True,
    ) -> BusMessage:
        """The job's status message, recorded on the bus and ROS 2 channels and as a state change (unless ``record`` is
        false).
        """
        message = status_message(self.task, state, finished_at, error, outputs, warnings)
        if record:
            self.record_published(message)
            self.recorder.write(
                TOPIC_STATE,
                StateChangeRecord(job_id=self.task.job_id, state=state, at=finished_at or utc_now(), error=error),
            )
        return message


def status_message(
    task: JobTask,
    state: str,
    finished_at: str | None = None,
    error: str | None = None,
    outputs: list[str] | None = None,
    warnings: list[str] | None = None,
) -> BusMessage:
    """The status message of ``task`` in ``state`` (times UTC ISO 8601)."""
    body = StatusMessage(
        job_id=task.job_id,
        state=state,
        folder=task.folder,
        attempt=task.attempt,
        queued_at=task.queued_at,
        started_at=task.started_at,
        finished_at=finished_at,
        error=error,
        outputs=outputs or [],
        warnings=warnings or [],
    )
    return BusMessage.json_body(task.config.bus.prefix, task.config.bus.cell, "status", body)
