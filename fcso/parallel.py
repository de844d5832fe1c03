"""Ordered parallel maps over forked worker processes, for the stages of a design.

Workers are forked once the data they read is ready, so the design's
samples, meshes and manifold3d solids reach them without being pickled;
only tasks and results cross. Results come back in task order, so a design
is the same for any number of workers.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any

# The shared data of the pool being forked: set by WorkerPool just before
# its workers fork, read only inside them.
_WORKER_CONTEXT: Any = None
#: prctl(2) option: the signal a process gets when its parent dies.
_PR_SET_PDEATHSIG = 1


def available_cores() -> int:
    """Cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def resolve_jobs(jobs: int) -> int:
    """Worker processes for a ``jobs`` setting: 0 means every available core."""
    return available_cores() if jobs <= 0 else jobs


def _call(task):
    function, item = task
    return function(_WORKER_CONTEXT, item)


def _started(_) -> int:
    return os.getpid()


def die_with_parent(parent_pid: int) -> None:
    """Have the kernel kill this process when its parent, ``parent_pid``, dies (Linux; elsewhere nothing).

    A forked worker whose parent is killed (the OOM killer, a daemon's job
    limit) would otherwise wait for work forever, holding memory and every
    file its parent had open.
    """
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):
        return
    if os.getppid() != parent_pid:  # the parent died before the request took effect
        os._exit(1)


class WorkerPool:
    """Forked workers that share one read-only ``context``; ``jobs = 1`` runs in this process.

    Parameters
    ----------
    context : object
        Data every task reads (inherited by fork, never pickled).
    jobs : int
        Worker processes.

    Use as a context manager; :meth:`map` returns results in task order.
    """

    def __init__(self, context: Any, jobs: int):
        self.context = context
        self.jobs = jobs
        self._pool: ProcessPoolExecutor | None = None

    def __enter__(self) -> WorkerPool:
        global _WORKER_CONTEXT
        if self.jobs > 1:
            _WORKER_CONTEXT = self.context
            try:
                self._pool = ProcessPoolExecutor(
                    self.jobs,
                    mp_context=multiprocessing.get_context("fork"),
                    initializer=die_with_parent,
                    initargs=(os.getpid(),),
                )
                # fork every worker now, while the context is the one to share
                list(self._pool.map(_started, [None] * self.jobs))
            finally:
                _WORKER_CONTEXT = None
        return self

    def __exit__(self, *exc) -> None:
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)
            self._pool = None

    def map(self, function: Callable[[Any, Any], Any], items: Sequence[Any], chunksize: int = 1) -> list:
        """``[function(context, item) for item in items]``, spread over the workers.

        ``function`` must be a module-level function; items and results are pickled.
        """
        if self._pool is None or len(items) <= 1:
            return [function(self.context, item) for item in items]
        return list(self._pool.map(_call, [(function, item) for item in items], chunksize=max(1, chunksize)))
