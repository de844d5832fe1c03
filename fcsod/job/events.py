"""What a worker process tells the daemon, one frozen dataclass per kind, sent pickled over the worker's pipe.

The worker (:mod:`fcsod.job.process`, :func:`fcsod.job.running.run_job`,
:func:`fcsod.job.verification.verify_again`) sends them in this order: one
:class:`WorkerReady` (or :class:`WorkerBroken`), then for a job
:class:`Log`, :class:`Publish`, :class:`Scene` and :class:`StepFinished`
as it goes and one :class:`JobFinished`; a verification, of a job just done
or again after a crash, sends :class:`VerificationStarted`, its
:class:`Log` lines and one :class:`VerificationFinished`. The daemon
(:mod:`fcsod.service.daemon`) dispatches on the type. This module imports
nothing heavy: the daemon's process loads it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..bus.messages import BusMessage


@dataclass(frozen=True)
class WorkerReady:
    """The worker imported the job's code and waits for its task."""

    pid: int


@dataclass(frozen=True)
class WorkerBroken:
    """The worker cannot import the job's code (a broken installation): every worker would die the same way."""

    error: str


@dataclass(frozen=True)
class Log:
    """A line for the daemon's log (the job's record has it already, where it is still open)."""

    level: str
    message: str
    fields: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Publish:
    """A message to sign, journal and publish now, while the job runs."""

    message: BusMessage


@dataclass(frozen=True)
class Scene:
    """A Foxglove scene update for the daemon's live server: protobuf bytes as recorded on ``topic``."""

    topic: str
    data: bytes
    log_time_ns: int


@dataclass(frozen=True)
class StepFinished:
    """One step of the job ended, for the metrics' stage times."""

    name: str
    seconds: float


@dataclass(frozen=True)
class JobFinished:
    """The job ended ``done`` or ``failed``; its output folder is in place.

    ``messages`` are published in order (the last ``status`` among them
    holds the finish time). ``verify_limit_seconds`` is set when a
    verification of the delivered design follows in this worker.
    """

    state: str
    error: str | None
    messages: list[BusMessage]
    verify_limit_seconds: float | None


@dataclass(frozen=True)
class VerificationStarted:
    """A done job's verification starts; the daemon stops it after ``time_limit_seconds``."""

    time_limit_seconds: float


@dataclass(frozen=True)
class VerificationFinished:
    """A done job's verification ended ``done``, ``failed`` or ``skipped``, with one message per verified design."""

    state: str
    error: str | None
    messages: list[BusMessage]


WorkerEvent = (
    WorkerReady
    | WorkerBroken
    | Log
    | Publish
    | Scene
    | StepFinished
    | JobFinished
    | VerificationStarted
    | VerificationFinished
)

#: How a job or a verification sends its events (the worker's ``connection.send``, or a list's append in tests).
Emit = Callable[[WorkerEvent], None]
