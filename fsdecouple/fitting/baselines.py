"""The five decoupling methods of Section 4, and training many of them in parallel.

Every fitted method has ``decouple(u, rotate=False)`` -> forces [N]:

* ``initial``: no coupling correction, ``f = omega^-1(u)`` per axis (Table 1, eq. 13);
* ``linear``: the industrial calibration matrix, ``f = C u`` by least squares (Section 1);
* ``rbf-mimo``: the standard MIMO RBF network of Section 4.1 (:mod:`fsdecouple.fitting.rbf`);
* ``rbf-siso``: the coupling error model with six 1-D RBF networks (Figure 7, red);
* ``svr``: the coupling error model with six epsilon-SVRs (Table 2, Table 3).
"""

from __future__ import annotations

import time
from concurrent.futures import as_completed
from dataclasses import dataclass

import numpy as np

from ..config import Settings
from ..core.decouple import initial_forces
from ..data.calibration import CalibrationSet
from .fit import chi_training_data, fit
from .linear import CalibrationMatrix, fit_calibration_matrix, fit_omega
from .threads import single_threaded_libraries, tasks_on, thread_pool

METHODS = ("initial", "linear", "rbf-mimo", "rbf-siso", "svr")


@dataclass(frozen=True)
class InitialMethod:
    """No coupling correction: ``f_a = u_a / k_aa`` (the "initial data" of Table 1)."""

    k: np.ndarray

    def decouple(self, u: np.ndarray, *, rotate: bool = False) -> np.ndarray:
        del rotate
        return initial_forces(u, self.k)


def input_scale(train: CalibrationSet, settings: Settings) -> np.ndarray | None:
    """RBF input units: volts as they are, or full-scale outputs as the SVRs see them."""
    if settings.scaling != "full_scale":
        return None
    return np.abs(fit_omega(train.points, train.layout).k) * np.asarray(settings.full_scale)


def establish(method: str, train: CalibrationSet, settings: Settings, *, workers: int = 1,
              tables: bool = True, noise_fraction: float | None = None):
    """Fit one method on a training set; the result has ``decouple(u, rotate=False)``.

    ``tables``: build the svr model's fast-path tables (not needed to score it);
    ``noise_fraction``: the svr's built-in solver tolerance (:func:`fit`).
    """
    if method == "initial" and train.layout.overdetermined:  # M > N: P u (gauges.py)
        from .gauges import forward_matrix
        return CalibrationMatrix(np.linalg.pinv(forward_matrix(train.forces, train.voltages)))
    if method == "initial":
        return InitialMethod(fit_omega(train.points, train.layout).k)
    if method == "linear":
        return fit_calibration_matrix(train.voltages, train.forces)
    if method in ("rbf-mimo", "rbf-siso"):  # scipy.linalg: cv's baselines only, not fit's
        from .rbf import SPREAD, fit_mimo, fit_siso
    if method == "rbf-mimo":
        return fit_mimo(train.voltages, train.forces, spread=SPREAD,
                        input_scale=input_scale(train, settings))
    if method == "rbf-siso":
        data = {name: chi_training_data(train, name) for name in train.layout.chi_names}
        return fit_siso(fit_omega(train.points, train.layout).k, data, spread=SPREAD,
                        input_scale=input_scale(train, settings), layout=train.layout)
    if method == "svr":
        return fit(train, settings, workers=workers, tables=tables, noise_fraction=noise_fraction)
    raise ValueError(f"unknown method {method!r}")


def train_all(jobs, settings, workers, progress, *, tables: bool = True,
              noise_fraction: float | None = None, seconds: dict | None = None
              ) -> tuple[dict, float]:
    """Fit every (key, method, train) job on ``workers`` threads; (models, wall seconds).

    libsvm and LAPACK release the GIL, so threads train in parallel; each model
    depends only on its own job, so the results equal sequential training.  In
    parallel, each svr job's N(N - 1) SVRs and its tables are tasks on one pool of
    ``workers`` threads that every svr job shares (:func:`~.threads.tasks_on`): three
    svr jobs on two threads keep both busy to the end, where one job per thread left
    one idle for the last job's whole fit.  Each job runs on a thread of its own that
    mostly waits for its tasks; the short baselines share one more.
    ``seconds``, if given, gets each key's time to fit alone: its wall time when
    sequential, else the CPU time of its own thread plus that of its tasks, whichever
    pool thread ran them (BLAS and OpenMP at one thread: its time alone on an idle core).
    """
    with single_threaded_libraries():
        return _train_all(jobs, settings, workers, progress, tables, noise_fraction,
                          {} if seconds is None else seconds)


def _train_all(jobs, settings, workers, progress, tables, noise_fraction,
               seconds) -> tuple[dict, float]:
    models = {}
    t0 = time.perf_counter()
    if workers <= 1:
        for i, (key, method, train) in enumerate(jobs, start=1):
            start = time.perf_counter()
            models[key] = establish(method, train, settings, workers=1, tables=tables,
                                    noise_fraction=noise_fraction)
            seconds[key] = time.perf_counter() - start
            if progress:
                progress(i, len(jobs))
        return models, time.perf_counter() - t0

    def timed(key, method, train):
        with tasks_on(pool) as tasks:
            start = time.thread_time()
            model = establish(method, train, settings, workers=workers, tables=tables,
                              noise_fraction=noise_fraction)
            seconds[key] = time.thread_time() - start + tasks.cpu
        return model

    # the svr jobs first, each on a thread of its own; the rest one after another
    order = sorted(jobs, key=lambda j: j[1] != "svr")
    svr_jobs = sum(1 for _, method, _ in jobs if method == "svr")
    with thread_pool(workers) as pool, thread_pool(svr_jobs + 1) as job_threads:
        futures = {job_threads.submit(timed, key, m, tr): key for key, m, tr in order}
        for i, fut in enumerate(as_completed(futures), start=1):
            models[futures[fut]] = fut.result()
            if progress:
                progress(i, len(jobs))
    return models, time.perf_counter() - t0
