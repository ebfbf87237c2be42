"""Threads: fsdecouple parallelises over whole jobs, and keeps BLAS and OpenMP to one thread.

Every matrix here is small (hundreds of rows) and fsdecouple runs whole jobs (the
SVRs of a fit, the models of cv, the blocks of a log) on its own threads; several
fits can share one pool's threads task by task (:func:`tasks_on`, cv's rounds).
OpenBLAS's and OpenMP's worker threads would only compete with those threads for
the cores, and their spin-waiting made cv up to 10x slower on a loaded 2-core
machine; a multi-threaded BLAS also changes the last digits of a least-squares
solve with the thread count.  So the heavy calls run inside
:func:`single_threaded_libraries`, which limits the native thread pools for its
duration only (threadpoolctl, as scikit-learn does) instead of setting
``OMP_NUM_THREADS`` for the whole process.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor, wait

_lock = threading.Lock()
_depth = 0
_limits = None


@contextlib.contextmanager
def single_threaded_libraries() -> Iterator[None]:
    """BLAS and OpenMP pools at one thread inside the block, as they were after it.

    Re-entrant and thread-safe: the limits are process-wide, so they are set when
    the first block opens and restored when the last one (in any thread) closes.
    """
    global _depth, _limits
    with _lock:
        if _depth == 0:
            from threadpoolctl import threadpool_limits

            _limits = threadpool_limits(limits=1)
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0:
                _limits.restore_original_limits()
                _limits = None


@contextlib.contextmanager
def thread_pool(workers: int) -> Iterator[ThreadPoolExecutor | SharedTasks]:
    """A ThreadPoolExecutor that, when its block ends by an exception (Ctrl-C, SIGTERM),
    cancels the queued jobs and does not wait for the running ones: a stopped command
    stops now, not after every SVR already started (the CLI then exits without joining).

    Inside :func:`tasks_on` on the same thread, the block's tasks go to that shared pool
    instead (``workers`` is then the shared pool's), and leaving the block waits for them.
    """
    shared = getattr(_local, "tasks", None)
    if shared is not None:
        try:
            yield shared
        except BaseException:
            shared.cancel()
            raise
        shared.wait()
        return
    pool = ThreadPoolExecutor(workers)
    try:
        yield pool
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown()


_local = threading.local()


class SharedTasks:
    """One job's tasks on a pool that several jobs share, and their thread CPU time.

    Has the ``submit`` and ``map`` of an executor.  ``cpu`` [s] sums the thread CPU time
    of every task run so far, on whichever pool thread ran it: with the job's own
    thread's CPU time, the job's time to run alone on one idle core.
    """

    def __init__(self, pool: ThreadPoolExecutor):
        self._pool = pool
        self._futures: list[Future] = []
        self._lock = threading.Lock()
        self.cpu = 0.0

    def submit(self, fn: Callable, /, *args, **kwargs) -> Future:
        def timed():
            start = time.thread_time()
            try:
                return fn(*args, **kwargs)
            finally:
                spent = time.thread_time() - start
                with self._lock:
                    self.cpu += spent

        future = self._pool.submit(timed)
        self._futures.append(future)
        return future

    def map(self, fn: Callable, *iterables) -> Iterator:
        """``fn`` over the arguments as tasks, submitted at once; results in order."""
        futures = [self.submit(fn, *args) for args in zip(*iterables)]  # noqa: B905 (as Executor.map)

        def results():
            try:
                for future in futures:
                    yield future.result()
            finally:  # an error or an abandoned iterator: the rest are not wanted
                for future in futures:
                    future.cancel()

        return results()

    def wait(self) -> None:
        """Until every task submitted so far has finished."""
        wait(self._futures)

    def cancel(self) -> None:
        """Drop the queued tasks (the running ones finish on their pool threads)."""
        for future in self._futures:
            future.cancel()


@contextlib.contextmanager
def tasks_on(pool: ThreadPoolExecutor) -> Iterator[SharedTasks]:
    """Run the tasks of every :func:`thread_pool` opened on this thread, inside the block,
    on ``pool``: several jobs then share one pool's threads task by task, instead of one
    thread (or a pool of their own) each.

    A task that opens a :func:`thread_pool` itself gets a pool of its own (it runs on a
    thread of ``pool``, outside the block): it never waits for a pool it occupies.
    """
    tasks = SharedTasks(pool)
    outer = getattr(_local, "tasks", None)
    _local.tasks = tasks
    try:
        yield tasks
    finally:
        _local.tasks = outer
