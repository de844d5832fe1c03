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
from multiprocessing.connection import Connection

from fcso.parallel import die_with_parent

from .task import SIGNAL_TIME_LIMIT, SIGNAL_WITHDRAWN, TimeLimitExceeded, VerificationTask, Withdrawn

#: The job's code (fcso's design, MuJoCo, matplotlib), imported once by the fork server that workers are forked from.
WORKER_PRELOAD = ("fcsod.job.running", "fcsod.job.verification")


def _time_limit(signum, frame) -> None:
    raise TimeLimitExceeded()


def _withdrawn(signum, frame) -> None:
    raise Withdrawn()


def worker_main(connection: Connection) -> None:
    """Entry point of a worker process: announce readiness, take one job (or a done job's verification), run it,
    report, exit.

    Parameters
    ----------
    connection : Connection
        Duplex pipe to the daemon.
    """
    # the parent is the fork server, which exits when the daemon does (its pipe from the daemon closes)
    die_with_parent(os.getppid())
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
        connection.send(("broken", f"{type(exc).__name__}: {exc}"))
        raise

    connection.send(("ready", os.getpid()))
    task = connection.recv()
    if task is None:
        return
    if isinstance(task, VerificationTask):
        verify_again(task, connection.send)
    else:
        run_job(task, connection.send)
    connection.close()
