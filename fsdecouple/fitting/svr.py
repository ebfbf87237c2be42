"""The one module that imports libsvm: fit an epsilon-SVR, return plain arrays.

A fitted SVR is eq. (10), ``f(x) = sum_i (a_i - a_i*) k(x_i, x) + b``; libsvm
stores the dual coefficients ``a_i - a_i*`` as ``sv_coef`` and ``rho = -b``.
"""

from __future__ import annotations

import functools
import threading
from dataclasses import dataclass

import numpy as np
from libsvm import svmutil

from ..config import SVRSettings
from ..errors import FsdecoupleError
from .threads import single_threaded_libraries


@dataclass(frozen=True)
class SVRFit:
    """One fitted epsilon-SVR with a single input, as plain arrays.

    Attributes
    ----------
    support_vectors : ndarray, shape (n_sv,)
        The support vectors x_i (in the scaled input units the SVR saw).
    dual_coef : ndarray, shape (n_sv,)
        a_i - a_i* of eq. (10).
    rho : float
        -b of eq. (10).
    gamma : float
        RBF kernel parameter, k(x, x') = exp(-gamma (x - x')^2).
    """

    support_vectors: np.ndarray
    dual_coef: np.ndarray
    rho: float
    gamma: float


def train(x: np.ndarray, y: np.ndarray, params: SVRSettings):
    """Train libsvm's epsilon-SVR (``-s 3 -t 2``) on points in the given order.

    Returns libsvm's own model object (for tests that compare predictions).
    """
    x = np.ascontiguousarray(x, dtype=float).reshape(-1, 1)
    y = np.ascontiguousarray(y, dtype=float).ravel()
    if x.shape[0] != y.size or y.size < 2:
        raise FsdecoupleError(f"an SVR needs at least 2 points, got {y.size}")
    with single_threaded_libraries():
        return _off_the_main_thread(_svm_train, y, x, params.libsvm_options())


@functools.cache
def _controller():
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()  # the libraries loaded now, libsvm's OpenMP among them


def _svm_train(y, x, options):
    # OpenMP's thread count is a setting of each thread: set it on the one that trains (a
    # pool's, or _off_the_main_thread's), or libsvm spawns a thread per core for each SVR
    with _controller().limit(limits=1, user_api="openmp"):
        return svmutil.svm_train(y, x, options)


def _off_the_main_thread(fn, *args):
    """``fn(*args)`` on a daemon thread while the main thread waits in short joins.

    libsvm calls back into Python to print (``-q``: to print nothing).  A SIGTERM or
    Ctrl-C that arrives during training runs its handler inside that callback, where
    ctypes ignores the exception it raises ("Exception ignored on calling ctypes
    callback function"), and training went on until SIGKILL.  Waiting here, the main
    thread handles the signal within a join's timeout and unwinds (temporary files
    removed); the daemon thread dies with the process.  Other threads call directly.
    """
    if threading.current_thread() is not threading.main_thread():
        return fn(*args)
    box: dict = {}

    def run():
        try:
            box["value"] = fn(*args)
        except BaseException as err:  # noqa: BLE001 (re-raised on the main thread)
            box["error"] = err

    worker = threading.Thread(target=run, name="libsvm", daemon=True)
    worker.start()
    while worker.is_alive():
        worker.join(0.05)
    if "error" in box:
        raise box["error"]
    return box["value"]


def extract(model, gamma: float) -> SVRFit:
    """Densify libsvm's sparse support vectors (1-based keys, zeros dropped)."""
    n = model.get_nr_sv()
    sv = np.array([row.get(1, 0.0) for row in model.get_SV()], dtype=float)
    coef = np.array([c[0] for c in model.get_sv_coef()], dtype=float)
    assert sv.size == coef.size == n
    return SVRFit(sv, coef, float(model.rho[0]), float(gamma))


def fit_svr(x: np.ndarray, y: np.ndarray, params: SVRSettings) -> SVRFit:
    """Fit one corrected coupling function chi by epsilon-SVR (Section 2.2, Table 2)."""
    return extract(train(x, y, params), params.gamma)


def predict(model, x: np.ndarray) -> np.ndarray:
    """libsvm's own prediction, for checking the numpy evaluator."""
    x = np.ascontiguousarray(x, dtype=float).reshape(-1, 1)
    with single_threaded_libraries():
        values, _, _ = svmutil.svm_predict(np.zeros(x.shape[0]), x, model, "-q")
    return np.asarray(values, dtype=float)
