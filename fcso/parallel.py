"""Ordered parallel maps for the stages of a design: forked local workers, or a Dask cluster.

The one executor interface of the design's fan-out (sampling, pad
geometries, screening, exact re-evaluations, solo qualities, set
screenings): :class:`WorkerPool`, a context manager whose :meth:`map` calls
a module-level function on a shared read-only context and each item.

- Locally (the default, no set-up), workers are forked once the data they
  read is ready, so the design's samples, meshes and manifold3d solids reach
  them without being pickled; only tasks and results cross.
- With a scheduler address (``[compute] scheduler``, CLI ``--scheduler``)
  the context is sent once to every worker of that Dask distributed
  cluster and the items go in batches, each a pure task (no files, no bus);
  Dask runs a task again elsewhere when its worker dies, so a lost worker
  costs a retry, not the job.

Results come back in task order, so a design is the same for any number of
workers and on either executor.
"""

from __future__ import annotations

import ctypes
import gc
import multiprocessing
import os
import signal
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any

from .errors import ComputeError

#: Batches per Dask worker thread in one map: enough to balance uneven tasks, few enough that each carries work.
_DASK_BATCHES_PER_THREAD = 4
#: Dask clients by scheduler address, opened once per process (several designs and daemons share one cluster).
_DASK_CLIENTS: dict[str, Any] = {}

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


def fork_safe_manifold() -> None:
    """Start manifold3d's thread pool (TBB) with no worker threads, once, before this process's first Boolean.

    TBB is not fork-safe: a worker forked while its parent's TBB threads
    exist waits for them forever in its first Boolean (a design hung so in
    ``pad_geometry``). TBB sizes its pool once, from the CPU affinity of its
    first parallel call, so that call is made on one CPU and the affinity
    restored: every Boolean then runs on its calling thread, and fcso's
    parallelism is its worker processes. Elsewhere than Linux, nothing.
    """
    if not hasattr(os, "sched_setaffinity"):
        return
    import manifold3d

    cpus = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {min(cpus)})
    try:
        (manifold3d.Manifold.cube([2.0, 2.0, 2.0]) - manifold3d.Manifold.sphere(1.0, 16)).volume()
    finally:
        os.sched_setaffinity(0, cpus)


def resolve_jobs(jobs: int) -> int:
    """Worker processes for a ``jobs`` setting: 0 means every available core."""
    return available_cores() if jobs <= 0 else jobs


def _call(task):
    function, item = task
    return function(_WORKER_CONTEXT, item)


def _started(_) -> None:
    """A task that only makes the pool fork its workers."""


def _call_batch(function: Callable[[Any, Any], Any], context: Any, items: list) -> list:
    """One Dask task: ``function`` on a batch of items (pure: it reads the context, returns results)."""
    return [function(context, item) for item in items]


def dask_client(address: str):
    """The Dask distributed client of ``address``, connected once per process.

    Raises
    ------
    ComputeError
        The scheduler cannot be reached (the message names the address).
    """
    client = _DASK_CLIENTS.get(address)
    if client is None or client.status != "running":
        from distributed import Client  # imported only when a cluster is asked for

        try:
            client = Client(address, set_as_default=False, timeout="20s")
        except OSError as error:
            raise ComputeError(f"[compute] scheduler {address}: cannot connect ({error})") from error
        _DASK_CLIENTS[address] = client
    return client


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
        Data every task reads (inherited by fork, never pickled; sent once to
        every worker of a Dask cluster).
    jobs : int
        Worker processes (local only).
    scheduler : str, optional
        Address of a Dask distributed scheduler, e.g. ``tcp://host:8786``:
        tasks run on its workers instead of local processes.

    Use as a context manager; :meth:`map` returns results in task order.
    """

    def __init__(self, context: Any, jobs: int, scheduler: str | None = None):
        self.context = context
        self.jobs = jobs
        self.scheduler = scheduler
        self._pool: ProcessPoolExecutor | None = None
        self._workers: list[multiprocessing.process.BaseProcess] = []
        self._stopped = False
        self._client = None
        self._context_future = None

    def __enter__(self) -> WorkerPool:
        global _WORKER_CONTEXT
        if self.scheduler:
            self._client = dask_client(self.scheduler)
            # once per pool, to every worker: tasks then carry only their items (in a list, or a tuple context would
            # be scattered item by item)
            self._context_future = self._client.scatter([self.context], broadcast=True, hash=False)[0]
        elif self.jobs > 1:
            _WORKER_CONTEXT = self.context
            # everything the workers inherit is left out of their garbage collections, which would otherwise write
            # to every inherited object and so copy its memory page into the worker
            gc.freeze()
            try:
                forked_before = {process.pid for process in multiprocessing.active_children()}
                self._pool = ProcessPoolExecutor(
                    self.jobs,
                    mp_context=multiprocessing.get_context("fork"),
                    initializer=die_with_parent,
                    initargs=(os.getpid(),),
                )
                # fork every worker now, while the context is the one to share
                list(self._pool.map(_started, [None] * self.jobs))
                # this pool's workers (one of them may have run every start task: their pids would miss the others)
                self._workers = [p for p in multiprocessing.active_children() if p.pid not in forked_before]
            finally:
                gc.unfreeze()
                _WORKER_CONTEXT = None
        return self

    def __exit__(self, *exc) -> None:
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)
            self._pool = None
        if self._context_future is not None:
            self._context_future.release()
            self._context_future = None

    def map(self, function: Callable[[Any, Any], Any], items: Sequence[Any], chunksize: int = 1) -> list:
        """``[function(context, item) for item in items]``, spread over the workers.

        ``function`` must be a module-level function; items and results are pickled.
        """
        return self.map_later(function, items, chunksize)()

    def map_later(
        self, function: Callable[[Any, Any], Any], items: Sequence[Any], chunksize: int = 1
    ) -> Callable[[], list]:
        """:meth:`map` started now on the workers, its results taken later: this process is free meanwhile.

        Returns a function that waits for the results and returns them in
        task order; call it once, before the pool closes. With no workers
        (``jobs = 1``) the tasks run in this process when it is called.
        """
        self._check_open()
        items = list(items)
        if self._client is not None and items:
            return self._dask_map_later(function, items)
        if self._pool is None or len(items) <= 1:
            return lambda: [function(self.context, item) for item in items]
        results = self._pool.map(_call, [(function, item) for item in items], chunksize=max(1, chunksize))
        return lambda: list(results)

    def run(
        self,
        tasks: Sequence[tuple[Callable[[Any, Any], Any], Any, Any]],
        on_done: Callable[[Any, Any], Sequence[tuple[Callable[[Any, Any], Any], Any, Any]]],
        settled: Callable[[], bool] = lambda: False,
    ) -> None:
        """Run ``(function, item, tag)`` tasks as workers free up; each result goes to ``on_done(tag, result)``.

        ``on_done`` is called in this process as each task finishes, in the
        order they finish, and returns further tasks to run (those that
        waited for it): a stage's task starts as soon as what it needs is
        made, not after the whole previous stage. What it records must not
        depend on that order.

        ``settled`` is asked after each ``on_done``: once it returns True the
        run returns at once, and the tasks still running are abandoned
        (their results are not needed, e.g. the grasps beyond a failure
        that decided a verification): the local workers are killed and the
        pool takes no further tasks; a cluster's futures are cancelled.
        """
        self._check_open()
        if self._client is not None:
            self._dask_run(list(tasks), on_done, settled)
            return
        if self._pool is None:
            queue = list(tasks)
            while queue and not settled():
                function, item, tag = queue.pop(0)
                queue.extend(on_done(tag, function(self.context, item)))
            return
        running = {self._pool.submit(_call, (function, item)): tag for function, item, tag in tasks}
        while running and not settled():
            finished, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in finished:
                tag = running.pop(future)
                for function, item, next_tag in on_done(tag, future.result()):
                    running[self._pool.submit(_call, (function, item))] = next_tag
                if settled():
                    break
        if running:
            self._stop_workers()

    def _stop_workers(self) -> None:
        """Kill the local workers, whatever they are running, and close the pool."""
        # every worker: one left alive may wait for ever on the task queue's lock that a killed one held
        for worker in self._workers:
            worker.kill()
        # the executor sees its workers die, fails what was queued and reaps them
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._pool = None
        self._workers = []
        self._stopped = True

    def _check_open(self) -> None:
        if self._stopped:
            raise RuntimeError("this pool's workers were killed when a run settled: open a new pool")

    def _dask_run(self, tasks: list, on_done, settled: Callable[[], bool]) -> None:
        """:meth:`run` on the Dask cluster."""
        from distributed import as_completed

        def submit(function, item):
            return self._client.submit(_call_batch, function, self._context_future, [item], pure=False)

        running = {submit(function, item): tag for function, item, tag in tasks}
        finished = as_completed(list(running), loop=self._client.loop)
        for future in finished:
            tag = running.pop(future)
            for function, item, next_tag in on_done(tag, future.result()[0]):
                follower = submit(function, item)
                running[follower] = next_tag
                finished.add(follower)
            if settled():
                self._client.cancel(list(running))
                return

    def _dask_map_later(self, function: Callable[[Any, Any], Any], items: list) -> Callable[[], list]:
        """:meth:`map_later` on the Dask cluster: items in contiguous batches, results gathered in order."""
        threads = max(1, sum(self._client.nthreads().values()))
        size = max(1, -(-len(items) // (_DASK_BATCHES_PER_THREAD * threads)))
        futures = [
            self._client.submit(_call_batch, function, self._context_future, items[i : i + size], pure=False)
            for i in range(0, len(items), size)
        ]
        return lambda: [result for batch in self._client.gather(futures) for result in batch]
