"""Zero offsets from all points of a sweep, jointly with the fit (``zero: fit``).

Section 3 zero-corrects each sweep by its zero-load rows (:func:`fsdecouple.zero.zero_correct`,
``zero: rows``).  With one zero row per sweep, every sweep carries that row's noise as
an offset, and every chi inherits the mean of those offsets over the repetitions.

``zero: fit`` keeps the model of Section 2 and lets every point of a sweep speak for
its zero.  In the sweep of component b, repetition r (offsets o relative to the
zero-row correction already applied):

* the prime output follows omega through the origin, ``u_b = o_b,r + k_bb f_b``
  (eq. 2): one least-squares fit with a common slope and one intercept per sweep;
* each other output follows its corrected coupling function through zero,
  ``u_a = o_a,r + chi_ab(u_b - o_b,r)`` with ``chi_ab(0) = 0`` (eq. 4: no load, no
  coupling).  chi_ab is the model's own epsilon-SVR; the offsets and chi are found by
  alternating: fit chi to the corrected points, move each sweep's offset by its mean
  residual, and move all of them by chi(0), so that the refitted chi passes through
  zero.

The zero rows stay in the sweep as ordinary points at f = 0.  Held-out test points
(cv, the verdict) keep the zero-row correction, as a task log keeps its tare.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from .axes import AXES, FORCE_COLUMNS, VOLTAGE_COLUMNS
from .kernel import rbf_sum

if TYPE_CHECKING:
    from .calibration import CalibrationSet
    from .config import SVRSettings

# Alternations of chi fit and offset update.  Each removes the part of the offsets'
# error that chi's smoothness can tell from its shape; the change after the third
# is far below the noise on every simulated sensor (tests/test_zero_fit.py).
ITERATIONS = 3


def _prime_offsets(f: np.ndarray, u: np.ndarray, sweep: np.ndarray, n: int) -> np.ndarray:
    """Per-sweep intercepts of ``u = o_s + k f`` with one common slope k (eq. 2)."""
    design = np.zeros((f.size, 1 + n))
    design[:, 0] = f
    design[np.arange(f.size), 1 + sweep] = 1.0
    coef, *_ = np.linalg.lstsq(design, u, rcond=None)
    return coef[1:]


def _chi_offsets(x: np.ndarray, y: np.ndarray, sweep: np.ndarray, n: int,
                 in_scale: float, out_scale: float, svr: SVRSettings, fit_svr) -> np.ndarray:
    """Per-sweep offsets of ``y = o_s + chi(x)`` with chi(0) = 0, chi an epsilon-SVR."""
    shift = np.zeros(n)
    count = np.bincount(sweep, minlength=n)
    for _ in range(ITERATIONS):
        yc = y - shift[sweep]
        s = fit_svr(x / in_scale, yc / out_scale, svr)
        at = rbf_sum(np.append(x / in_scale, 0.0), s.support_vectors, s.dual_coef, s.gamma,
                     -s.rho) * out_scale
        resid = yc - at[:-1]
        shift += np.bincount(sweep, weights=resid, minlength=n) / count + at[-1]
    return shift


def fit_offsets(calib: CalibrationSet, svr: SVRSettings, scale: np.ndarray, fit_svr) -> CalibrationSet:
    """The calibration set with each sweep's offsets estimated from all its points.

    ``scale`` is the kernel scaling of each output (as the fit uses it), ``fit_svr``
    the SVR trainer.  The offsets table grows by the shifts found, so ``ingest`` and
    the model's provenance show the whole offset removed.
    """
    points = calib.points.copy()
    u = points[list(VOLTAGE_COLUMNS)].to_numpy(dtype=float, copy=True)
    offsets = calib.offsets.copy()
    for b, axis in enumerate(AXES):
        rows = np.flatnonzero((points["axis"] == axis).to_numpy())
        if not rows.size:
            continue
        reps, sweep = np.unique(points["repetition"].to_numpy()[rows], return_inverse=True)
        n = reps.size
        f = points[FORCE_COLUMNS[b]].to_numpy(dtype=float)[rows]
        shift = np.zeros((n, len(AXES)))
        shift[:, b] = _prime_offsets(f, u[rows, b], sweep, n)
        x = u[rows, b] - shift[sweep, b]
        for a in range(len(AXES)):
            if a != b:
                shift[:, a] = _chi_offsets(x, u[rows, a], sweep, n, float(scale[b]),
                                           float(scale[a]), svr, fit_svr)
        u[rows] -= shift[sweep]
        at = (offsets["axis"] == axis).to_numpy()
        index = {int(r): k for k, r in enumerate(reps)}
        for k, row in zip(np.flatnonzero(at), offsets.loc[at, "repetition"], strict=True):
            if int(row) in index:
                for c, col in enumerate(VOLTAGE_COLUMNS):
                    offsets.iat[k, offsets.columns.get_loc(col)] += shift[index[int(row)], c]
    for c, col in enumerate(VOLTAGE_COLUMNS):
        points[col] = u[:, c]
    return replace(calib, points=points, offsets=offsets)
