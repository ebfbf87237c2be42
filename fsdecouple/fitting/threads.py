"""Threads: fsdecouple parallelises over whole jobs, and keeps BLAS and OpenMP to one thread.

Every matrix here is small (hundreds of rows) and fsdecouple runs whole jobs (the
SVRs of a fit, the models of cv, the blocks of a log) on its own threads.
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
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor

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
def thread_pool(workers: int) -> Iterator[ThreadPoolExecutor]:
    """A ThreadPoolExecutor that, when its block ends by an exception (Ctrl-C, SIGTERM),
    cancels the queued jobs and does not wait for the running ones: a stopped command
    stops now, not after every SVR already started (the CLI then exits without joining)."""
    pool = ThreadPoolExecutor(workers)
    try:
        yield pool
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown()
