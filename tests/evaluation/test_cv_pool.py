"""cv's training pool (fitting/baselines.py::train_all, fitting/threads.py::tasks_on).

In parallel, every svr job's SVRs are tasks on one pool that all jobs share, and a job's
time alone (cv's Table 4) is the CPU time of its own thread plus that of its tasks.  The
expected figures here are measured independently, inside the jobs and tasks themselves.
"""

from __future__ import annotations

import threading
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from fsdecouple.fitting import baselines
from fsdecouple.fitting.baselines import train_all
from fsdecouple.fitting.threads import tasks_on, thread_pool

BURN = 0.01  # [s] of thread CPU time each fake task spends


def _burn(seconds: float) -> float:
    """Spend ``seconds`` of this thread's CPU time; the CPU time spent, measured here."""
    start = time.thread_time()
    while time.thread_time() - start < seconds:
        sum(i * i for i in range(200))
    return time.thread_time() - start


def _task(_):
    return threading.current_thread().name, _burn(BURN)


def test_thread_pool_inside_tasks_on_runs_its_tasks_on_the_shared_pool():
    with ThreadPoolExecutor(2, thread_name_prefix="shared") as pool:
        with tasks_on(pool) as tasks:
            with thread_pool(8) as inner:  # 8: the shared pool's 2 threads run them all
                results = list(inner.map(_task, range(6)))
                late = inner.submit(_task, 6)
            assert late.done()  # leaving the block waited for its tasks
            results.append(late.result())
        with thread_pool(2) as own:  # after the block: a pool of its own again
            assert isinstance(own, ThreadPoolExecutor)
            assert not own.submit(_task, 0).result()[0].startswith("shared")
    names = {name for name, _ in results}
    assert all(n.startswith("shared") for n in names) and len(names) <= 2
    # cpu sums what each task measured itself, plus the wrapper's few microseconds
    spent = sum(cpu for _, cpu in results)
    assert spent >= 7 * BURN
    assert spent <= tasks.cpu <= spent + 1e-3 * len(results)


def test_a_task_that_opens_a_pool_gets_one_of_its_own():
    """A task on the only thread of the shared pool waiting for tasks on that pool would
    wait for ever: its own thread_pool is a pool of its own."""

    def nested(_):
        with thread_pool(2) as inner:
            return sorted(inner.map(lambda i: i * i, range(4)))

    with ThreadPoolExecutor(1) as pool, tasks_on(pool), thread_pool(2) as outer:
        future = outer.submit(nested, 0)
        assert future.result(timeout=30) == [0, 1, 4, 9]


def test_an_error_in_the_block_drops_its_queued_tasks():
    release = threading.Event()
    with ThreadPoolExecutor(1) as pool:
        with tasks_on(pool), pytest.raises(RuntimeError, match="stop"), thread_pool(1) as inner:
            running = inner.submit(release.wait, 30)
            queued = [inner.submit(_task, i) for i in range(3)]
            raise RuntimeError("stop")
        assert all(f.cancelled() for f in queued)
        release.set()
        assert running.result(timeout=30) is True


class _Fitted:
    def __init__(self, method, task_threads, own_cpu, task_cpu):
        self.method, self.task_threads = method, task_threads
        self.own_cpu, self.task_cpu = own_cpu, task_cpu


def _fake_establish(method, train, settings, *, workers, tables, noise_fraction):
    """A job as fit runs one: work on its own thread, then its tasks on thread_pool(workers)
    (fit.py's ``pool.map(one, jobs)``); the CPU times measured here, by the job itself."""
    start = time.thread_time()
    _burn(BURN)
    task_threads, task_cpu = [], 0.0
    if method == "svr":
        with thread_pool(workers) as pool:
            for name, cpu in pool.map(_task, range(6)):
                task_threads.append(name)
                task_cpu += cpu
    return _Fitted(method, task_threads, time.thread_time() - start, task_cpu)


def test_train_all_shares_one_pool_and_times_each_job_by_its_threads_cpu(monkeypatch):
    monkeypatch.setattr(baselines, "establish", _fake_establish)
    jobs = [((r, m), m, None) for r in (1, 2, 3) for m in baselines.METHODS]
    seconds: dict = {}
    models, wall = train_all(jobs, None, 2, None, seconds=seconds)
    assert set(models) == set(seconds) == {key for key, _, _ in jobs}
    svr = [models[(r, "svr")] for r in (1, 2, 3)]
    # every svr job's SVRs ran on the one shared pool of 2 threads (one job per thread,
    # each with a pool of its own, would show 3 or more threads)
    task_threads = {name for m in svr for name in m.task_threads}
    assert len(task_threads) <= 2
    for key, model in models.items():
        # its own thread's CPU (which includes waiting, for no CPU) plus its tasks'
        expected = model.own_cpu + model.task_cpu
        assert expected <= seconds[key] + 1e-3
        assert seconds[key] <= expected + 1e-3 * (1 + len(model.task_threads)), key
    assert all(seconds[(r, "svr")] >= 7 * BURN for r in (1, 2, 3))
    assert np.isfinite(wall) and wall > 0


def test_train_all_of_nothing():
    assert train_all([], None, 2, None, seconds={}) == ({}, pytest.approx(0, abs=1.0))
    assert train_all([], None, 1, None)[0] == {}
