"""The worker process: forked for the daemon by a fork server, it takes one job, runs it and exits.

The fork server (multiprocessing's ``forkserver``, a fresh interpreter the
daemon starts, never a fork of the daemon and its bus threads) imports
:data:`WORKER_PRELOAD` once; each worker is a fork of it, so a job starts
without a new interpreter's imports. The daemon imports this module to
start workers, so it imports only what that needs.
"""

from __future__ import annotations

import os
import signal
import threading
from multiprocessing.connection import Connection

from .events import Emit, WorkerBroken, WorkerEvent, WorkerReady
from .task import SIGNAL_TIME_LIMIT, SIGNAL_WITHDRAWN, TimeLimitExceeded, VerificationTask, Withdrawn

#: The job's code (fcso's design, MuJoCo, matplotlib), imported once by the fork server that workers are forked from.
WORKER_PRELOAD = ("fcsod.job.running", "fcsod.job.verification")


def _time_limit(signum, frame) -> None:
    raise TimeLimitExceeded()


def _withdrawn(signum, frame) -> None:
    raise Withdrawn()


def _die_with_daemon(life_line: Connection) -> None:
    """Kill this process once the daemon is gone: the read end of a pipe only the daemon writes to ends then."""
    try:
        life_line.recv_bytes()
    except (EOFError, OSError):
        pass
    os.kill(os.getpid(), signal.SIGKILL)


def _to_daemon(connection: Connection) -> Emit:
    """``connection.send``, but a worker whose daemon is gone (kill -9) ends itself quietly, as its life line would
    end it a moment later, instead of dying of a broken pipe with a traceback in the daemon's log."""

    def send(event: WorkerEvent) -> None:
        try:
            connection.send(event)
        except (BrokenPipeError, ConnectionResetError):
            os.kill(os.getpid(), signal.SIGKILL)

    return send


def worker_main(connection: Connection, life_line: Connection) -> None:
    """Entry point of a worker process: announce readiness, take one job (or a done job's verification), run it,
    report, exit.

    Parameters
    ----------
    connection : Connection
        Duplex pipe to the daemon.
    life_line : Connection
        Read end of a pipe whose write end only the daemon holds (it never writes): it ends when the daemon dies.
    """
    # the parent is the fork server, which outlives the daemon as long as a worker it forked does (each holds its
    # pipe), so PR_SET_PDEATHSIG cannot tie the worker to the daemon: a kill -9 of the daemon ends the life line. The
    # design's own workers die with this one (fcso.parallel.die_with_parent).
    threading.Thread(target=_die_with_daemon, args=(life_line,), name="die-with-daemon", daemon=True).start()
    # Ctrl-C in a terminal reaches the whole process group: the daemon decides what happens to jobs
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(SIGNAL_TIME_LIMIT, _time_limit)
    signal.signal(SIGNAL_WITHDRAWN, _withdrawn)
    # the job's code is imported by the fork server (WORKER_PRELOAD); where that failed, it is imported here and a
    # failure is reported, before the worker says it is ready
    try:
        from .running import run_job
        from .verification import verify_again
    except Exception as exc:
        # a broken installation (a dependency missing or changed): every worker would die the same way, so the
        # daemon is told why instead of starting the next one
        connection.send(WorkerBroken(f"{type(exc).__name__}: {exc}"))
        raise

    send = _to_daemon(connection)
    send(WorkerReady(os.getpid()))
    try:
        task = connection.recv()
    except EOFError:
        # the daemon died before it handed a task (its life line ends this process too)
        return
    if task is None:
        return
    if isinstance(task, VerificationTask):
        verify_again(task, send)
    else:
        run_job(task, send)
    connection.close()
