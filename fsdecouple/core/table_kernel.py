"""Eq. (11) from the chi tables, compiled: one pass over the rows, everything in registers.

The table path (:mod:`fsdecouple.core.table_path`) calls it for large calls only
(COMPILED_WORK): numba, scipy and the cached kernel take ~0.45 s to load.

    f_a = u_a / k_a + h_a(u_a) + sum_{b != a} g_ab(p_b),   g_ab = -chi_ab / k_a,   eq. (11)

with h_a = -chi_aa / k_a the own-load chi of a joint fit (0 without one; always at the
measured u_a, :mod:`fsdecouple.fitting.joint`), p = u, or after K fixed-point steps
p_a <- k_a f_a (second-order refinement, eqs. 5-6; :mod:`fsdecouple.core.decouple`).
A row's table index per input b is t_b = (p_b - lo_b) / step_b, its interval int(t_b)
and its offset s_b = t_b - int(t_b); each g_ab is the cubic ((c3 s + c2) s + c1) s + c0 of that interval.

The arithmetic is the numpy kernel's (:func:`fsdecouple.core.table_path.eq11_rows`) and
the plain-Python evaluator's (:meth:`TableDecoupler.one`), with the same
:func:`~fsdecouple.core.surrogate.horner` step compiled, operation for operation, in
the same order and without fused multiply-adds (numba leaves LLVM's contraction off
unless ``fastmath`` is asked), so all three give the same bits; tests hold them to
it.  numba is the standard compiler for numeric loops in Python: numpy alone needs
one pass over memory per operation, seven per chi: on six axes it decouples 5-6 M
rows/s of a million, the kernel 12-14; on three axes, with the thread pool's larger
blocks, the two come closer (row 1d of docs/benchmarks.md: numpy 0.86-1.97x the time).
"""

from __future__ import annotations

import os
import tempfile

import numpy as np
from numba import njit
from numba.core import config as numba_config

from .surrogate import horner


def cache_dir() -> str | None:
    """Where the compiled kernel is cached: ``NUMBA_CACHE_DIR`` when set, else the user's
    cache directory (``platformdirs``), never the installed package; None when that
    place cannot be written."""
    import platformdirs

    path = os.environ.get("NUMBA_CACHE_DIR") or os.path.join(
        platformdirs.user_cache_dir("fsdecouple"), "numba")
    try:
        os.makedirs(path, exist_ok=True)
        tempfile.TemporaryFile(dir=path).close()
    except OSError:
        return None
    return path


def _compiled(fn):
    """``fn`` compiled without the GIL, cached in :func:`cache_dir`, else compiled once
    per process.  numba picks its cache locator when the function is decorated and
    tries a user-given directory first; its other locators would write next to this
    file, so none of them is ever reached."""
    path = cache_dir()
    if path is None:
        return njit(nogil=True, error_model="numpy")(fn)
    before, numba_config.CACHE_DIR = numba_config.CACHE_DIR, path
    try:
        return njit(nogil=True, cache=True, error_model="numpy")(fn)
    except RuntimeError:  # numba: "cannot cache function ...: no locator available"
        return njit(nogil=True, error_model="numpy")(fn)
    finally:
        numba_config.CACHE_DIR = before


_horner = _compiled(horner)  # the one definition of the cubic step, compiled


@_compiled
def eq11_rows(u, lo, inv_step, intervals, inv_k, k, step_tol, tab, sum_b, sum_m, refine, own,
              has_own, out, inside, settled):  # pragma: no cover - compiled; tested through TableDecoupler
    """Forces of eq. (11) for the rows of ``u`` (n, N) into ``out`` (n, N), before any rotation.

    ``tab`` (N, N - 1, intervals, 4): coefficients c0..c3 of g_ab, for input b and
    its m-th fed output; ``sum_b``/``sum_m`` (N, N - 1): the (b, m) added into
    output a, in order.  ``own`` (N, intervals, 4): coefficients of h_a = -chi_aa / k_a on
    input a's grid, added at u when ``has_own``.  ``inside[r]`` is False where row r left a table (or held a
    NaN) at u or at a step: its ``out`` is then undefined, for the exact path to
    fill.  ``settled[r]`` is False where the last refinement step k f - p^K was not
    within ``step_tol``: its forces are NaN.
    """
    n, dim = u.shape
    fed = dim - 1
    s = np.empty(dim)
    index = np.empty(dim, np.intp)
    x = np.empty(dim)
    f = np.empty(dim)
    base = np.empty(dim)
    for r in range(n):
        for b in range(dim):
            x[b] = u[r, b]
        ok = True
        for step in range(refine + 1):
            for b in range(dim):
                t = (x[b] - lo[b]) * inv_step[b]
                if not (t >= 0.0 and t < intervals[b]):  # also NaN
                    ok = False
                    break
                index[b] = int(t)  # truncation = floor, as t >= 0
                s[b] = t - index[b]
            if not ok:
                break
            if step == 0:  # x = u: u_a / k_a, and the own-load term at the measured u_a
                for a in range(dim):
                    base[a] = u[r, a] * inv_k[a]
                    if has_own:
                        i, sa = index[a], s[a]
                        base[a] += _horner(own[a, i, 0], own[a, i, 1], own[a, i, 2], own[a, i, 3], sa)
            for a in range(dim):
                fa = base[a]
                for d in range(fed):
                    b, m = sum_b[a, d], sum_m[a, d]
                    i, sb = index[b], s[b]
                    fa += _horner(tab[b, m, i, 0], tab[b, m, i, 1], tab[b, m, i, 2], tab[b, m, i, 3], sb)
                f[a] = fa
            if step < refine:
                for a in range(dim):
                    x[a] = f[a] * k[a]  # p^(j+1) = k f
        inside[r] = ok
        done = True
        if ok and refine > 0:
            for a in range(dim):
                if not (abs(f[a] * k[a] - x[a]) <= step_tol[a]):  # also NaN
                    done = False
        settled[r] = done
        for a in range(dim):
            out[r, a] = f[a] if done else np.nan
