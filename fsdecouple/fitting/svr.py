"""The one module that imports libsvm: fit an epsilon-SVR, return plain arrays.

A fitted SVR is eq. (10), ``f(x) = sum_i (a_i - a_i*) k(x_i, x) + b``; libsvm
stores the dual coefficients ``a_i - a_i*`` as ``sv_coef`` and ``rho = -b``.
"""

from __future__ import annotations

import functools
import sys
import threading
from dataclasses import dataclass

import numpy as np

from ..config import SVRSettings
from ..errors import FsdecoupleError
from .threads import single_threaded_libraries

# libsvm's Python module imports scipy.sparse and numba if it can, for sparse and numpy
# input (its jit only converts scipy CSR matrices).  fsdecouple passes plain lists, the
# input libsvm reads without either, so neither is imported here: on the sample, 0.9 s of
# the 4.5 s of CPU of ``fit`` (numba 0.5 s, scipy.sparse 0.4 s; issue 30).  A library that
# is already loaded is left to libsvm.  Import this module from the main thread, before
# threads start (fitting's entry points do): another thread importing scipy or numba
# while libsvm loads would be refused.  Code calling libsvm directly in the same process
# then passes lists or dicts too (libsvm reads numpy arrays only when it found scipy).
_SKIPPED = [name for name in ("scipy", "numba") if name not in sys.modules]
try:
    for _name in _SKIPPED:
        sys.modules[_name] = None  # an ImportError for libsvm's optional imports
    from libsvm import svmutil
finally:
    for _name in _SKIPPED:
        if sys.modules.get(_name, 0) is None:
            del sys.modules[_name]


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
    with single_threaded_libraries():  # lists: libsvm's input without scipy (above)
        return _off_the_main_thread(_svm_train, y.tolist(), x.tolist(), params.libsvm_options())


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
        values, _, _ = svmutil.svm_predict([0.0] * x.shape[0], x.tolist(), model, "-q")
    return np.asarray(values, dtype=float)
