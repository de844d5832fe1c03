"""fcso.parallel.WorkerPool.run (tasks that start others as they finish) and map_later (a map whose results are taken
later), on forked workers and in this process."""

from __future__ import annotations

import multiprocessing
import os
import signal
import threading

import pytest

from fcso.parallel import WorkerPool


def _scaled(context, item: int) -> int:
    return context * item


def _summed(context, items: list[int]) -> int:
    return context + sum(items)


@pytest.mark.parametrize("jobs", [1, 2])
def test_run_starts_each_follower_with_what_it_waited_for(jobs):
    # pairs (1, 2), (3, 4), (5, 6) are scaled by the context (10); each pair's sum (plus the context) is a follower
    # started once both of its items are done: 10 + 10 + 20, 10 + 30 + 40, 10 + 50 + 60
    pairs = {0: (1, 2), 1: (3, 4), 2: (5, 6)}
    scaled: dict[int, int] = {}
    sums: dict[int, int] = {}

    def on_done(tag, result):
        kind, what = tag
        if kind == "sum":
            sums[what] = result
            return []
        scaled[what] = result
        pair = next(p for p, items in pairs.items() if what in items)
        if all(item in scaled for item in pairs[pair]):
            return [(_summed, [scaled[item] for item in pairs[pair]], ("sum", pair))]
        return []

    with WorkerPool(10, jobs) as pool:
        pool.run([(_scaled, item, ("scaled", item)) for items in pairs.values() for item in items], on_done)
    assert scaled == {1: 10, 2: 20, 3: 30, 4: 40, 5: 50, 6: 60}
    assert sums == {0: 40, 1: 80, 2: 120}


def test_run_raises_what_a_task_raised():
    with WorkerPool(0, 2) as pool, pytest.raises(ZeroDivisionError):
        pool.run([(_summed, [1], "fine"), (_scaled, 1, "fine too")], lambda tag, result: [(_divided, result, "bad")])


def _divided(context, item: int) -> float:
    return item / context


def _pid(context, item: int) -> int:
    return os.getpid()


@pytest.mark.parametrize("jobs", [1, 2])
def test_map_later_returns_in_task_order_after_other_work_on_the_pool(jobs):
    with WorkerPool(10, jobs) as pool:
        later = pool.map_later(_scaled, [1, 2, 3, 4])
        # the pool serves other maps while the first one's results wait
        assert pool.map(_scaled, [5, 6]) == [50, 60]
        where = pool.map_later(_pid, [0, 1])
        assert later() == [10, 20, 30, 40]
        assert (os.getpid() in where()) == (jobs == 1)
        assert pool.map_later(_scaled, [])() == []


def _blocked(context, item) -> None:
    """Tells its pid, then never returns."""
    context.put(os.getpid())
    threading.Event().wait()


def _told(context, item) -> int:
    """The pid ``_blocked`` tells, once it runs."""
    return context.get()


def test_a_settled_run_stops_the_workers_of_the_tasks_it_abandons():
    # a task that never ends runs beside one that returns its pid, and a third worker has no task; the run is settled
    # by that result: it returns, every worker is killed (one left waiting on the task queue would hang the pool's
    # shutdown), and the pool takes no more tasks
    told = multiprocessing.get_context("fork").SimpleQueue()
    seen = []
    children_before = set(multiprocessing.active_children())

    def on_done(tag, result):
        seen.append((tag, result))
        return []

    with WorkerPool(told, 3) as pool:
        workers = set(multiprocessing.active_children()) - children_before
        pool.run([(_blocked, None, "blocked"), (_told, None, "told")], on_done, settled=lambda: bool(seen))
        with pytest.raises(RuntimeError, match="killed"):
            pool.map(_pid, [0, 1])
    [(tag, pid)] = seen
    assert tag == "told" and pid != os.getpid()
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)
    assert len(workers) == 3 and {worker.exitcode for worker in workers} == {-signal.SIGKILL}
    assert set(multiprocessing.active_children()) <= children_before


def test_a_settled_run_in_this_process_starts_nothing_more():
    done = []

    def on_done(tag, result):
        done.append(tag)
        return [(_scaled, result, tag + 1)] if tag < 5 else []

    with WorkerPool(10, 1) as pool:
        pool.run([(_scaled, 1, 0)], on_done, settled=lambda: len(done) == 2)
    assert done == [0, 1]
