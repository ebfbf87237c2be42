"""The least-squares model of the single-axis sweeps that ``apply --interval`` is
centred on, and its error's variance at a row (Gauss-Markov) (issue 33).

Eq. (1) with eq. (3)'s coupling, each output the sum of one function of each load:
u_a = sum_b g_ab(f_b), g_ab(0) = 0 (g_aa is omega_a's line and its nonlinearity, g_ab
for a != b the coupling error element e_ab of eq. 3).  Here every g_ab is a polynomial
in s = f_b / L_b (L_b the largest calibrated |f_b|), fitted by least squares to the
raw outputs a of all the b sweeps together, with one offset per sweep:

    u_a = c_sweep + sum_{k=1..d_ab} beta_k s^k

(:func:`fsdecouple.data.zero.sweep_design`, as ``offset_design`` builds it, of every degree).  Each
offset rests on all its sweep's points, not its zero reading alone, and the shape on
all the repetitions.  The degree d_ab (1 to ``MAX_DEGREE``, at most two below the
load levels of one sweep) is the one that predicts held-out repetitions best:
each sweep left out in turn, the shape fitted to the others and the left-out sweep's
own offset taken as its residuals' mean (the paper's cross-validation by held-out
repetitions, Section 4).  A row's forces solve u = sum_b g_b(f_b) by Newton's method
from eq. (11)'s forces (:meth:`fsdecouple.core.interval_data.SweepModel.forces`, the
stored model's evaluator, which loading a model file needs without fitting).

Why not the SVR's chi.  The chi of eq. (4) are fitted with Table 2's epsilon = 1e-4
and C = 1000: they follow the repetitions' mean at every step, so the final model's
own error (each step's mean of n noisy readings, and each sweep's zero readings) is
a realisation fixed per sensor that no statistic of the calibration tells apart, and
the intervals could only guess its size.  A least-squares fit of the same sweeps has
an error of known covariance: with the reading noise s_a^2 (the fits' pooled residual
variance), beta_ab has covariance s_a^2 C_ab, C_ab the shape block of (X'X)^-1, so
g_a at a row errs with variance

    V_a = s_a^2 sum_b x(s_b)' C_ab x(s_b),    x(s) = (s, s^2, ..., s^d_ab),

and the row's forces, through the Jacobian J_ab = dg_a/df_b, with covariance
J^-1 diag(V) J^-T (the model's part) and J^-1 diag(s^2) J^-T (the reading's).  The
degree chosen from the data adds a scatter the chosen degree's variance leaves out
(1.15-1.7 times it, tests/evaluation/test_sweep_model.py), which the intervals' bias
tolerance absorbs (:mod:`fsdecouple.evaluation.intervals`).

The assumption: the sensor's outputs add one function of each load (eq. 1), each a
polynomial of at most ``MAX_DEGREE`` over the calibrated range, the readings
independent with one variance per output.  A load beyond the calibrated range is the
polynomials' extrapolation: those rows keep the status ``extrapolated``, and the
interval's centre there is eq. (11)'s refined forces (``SweepModel.inside``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from ..axes import Layout
from ..core.interval_data import MAX_DEGREE
from ..data.zero import rows_by_group, sweep_design

if TYPE_CHECKING:  # apply reads the model, never pandas (tests/core/test_fast.py)
    import pandas as pd

RANK_TOLERANCE = 1e-12  # of R's largest diagonal: a design column that is no new direction


def fit_sweep_model(points: pd.DataFrame, layout: Layout) -> dict[str, Any] | None:
    """The least-squares sweep model of a zero-rows calibration, or None where it
    cannot be fitted (a component without sweeps in two repetitions or more, a sweep
    of fewer than three load levels, a labelled point that loads another component,
    or more outputs than components).

    ``points``: the calibration's points (``repetition``, ``axis``, the loads and the
    outputs as eq. (11) takes them).  Returns ``{"model": {"peak": [L_b], "span":
    [[lo_b, hi_b]] (the calibrated loads), "shape": [[beta_ab (d_ab)] per output a]
    per component b, "covariance": [[C_ab (d_ab x d_ab)] per a] per b,
    "noise_variance": [s_a^2] [output unit^2]}, "deviations": sorted studentised
    residuals}``, JSON-ready.
    """
    n = layout.n
    if len(layout.outputs) != n or not {"repetition", "axis"} <= set(points.columns):
        return None
    loads = points[list(layout.loads)].to_numpy(dtype=float)
    u_all = points[list(layout.outputs)].to_numpy(dtype=float)
    labels = points["axis"].to_numpy()
    peak, span, shape, cov = [], [], [], []
    rss, dof = np.zeros(n), np.zeros(n)
    studentised = []
    for b, label in enumerate(layout.labels):
        mine = labels == label
        f = loads[mine, b]
        others = np.delete(loads[mine], b, axis=1)
        _, group = np.unique(points["repetition"].to_numpy()[mine], return_inverse=True)
        groups = int(group.max(initial=-1)) + 1
        # the fewest load levels of one sweep (loads measured, not nominal, differ in
        # every repetition: their union is no count of levels)
        levels = min((np.unique(f[idx]).size for idx in rows_by_group(group)), default=0)
        top = min(MAX_DEGREE, levels - 2)
        L = float(np.abs(f).max(initial=0.0))
        if groups < 2 or top < 1 or not L > 0 or np.any(others != 0.0) \
                or not np.isfinite(u_all[mine]).all():
            return None
        s, u = f / L, u_all[mine]
        degree = _cross_validated_degree(s, group, groups, u, top)
        peak.append(L)
        span.append([float(f.min()), float(f.max())])
        shape.append([]), cov.append([])
        for a in range(n):
            fitted = _least_squares(sweep_design(s, group, groups, int(degree[a])), u[:, a])
            if fitted is None:
                return None
            beta, full, r, lever = fitted
            rss[a] += float(r @ r)
            dof[a] += len(r) - beta.size
            studentised.append((a, r, lever))
            shape[b].append(beta[groups:].tolist())
            cov[b].append(full[groups:, groups:].tolist())
    if np.any(dof < 1):
        return None
    variance = rss / dof
    if not np.all(variance > 0):
        return None
    z = [r[lever < 1.0] / math.sqrt(variance[a]) / np.sqrt(1.0 - lever[lever < 1.0])
         for a, r, lever in studentised]
    return {"model": {"peak": peak, "span": span, "shape": shape, "covariance": cov,
                      "noise_variance": variance.tolist()},
            "deviations": np.sort(np.concatenate(z)).tolist()}


def _least_squares(X: np.ndarray, y: np.ndarray):
    """(beta, (X'X)^-1, residuals, leverages) by a QR decomposition, or None where X has
    no full column rank.  (X'X)^-1 = R^-1 R^-T is positive semi-definite however
    ill-conditioned X (plain powers of s on a one-sided grid), and made symmetric."""
    q, r = np.linalg.qr(X)
    diag = np.abs(np.diag(r))
    if not diag.min() > RANK_TOLERANCE * diag.max():
        return None
    r_inv = np.linalg.inv(r)
    beta = r_inv @ (q.T @ y)
    full = r_inv @ r_inv.T
    full = (full + full.T) / 2.0  # symmetric to the bit whatever order BLAS sums in
    return beta, full, y - X @ beta, np.einsum("ij,ij->i", q, q)


def _cross_validated_degree(s, group, groups, u, top) -> np.ndarray:
    """Per output, the degree 1..``top`` whose shape, fitted without one sweep, predicts
    that sweep best (its own offset its residuals' mean), summed over the sweeps; a
    degree the other sweeps cannot determine (too few levels) is not a candidate."""
    error = np.zeros((top, u.shape[1]))
    for held in range(groups):
        train, test = group != held, group == held
        _, g = np.unique(group[train], return_inverse=True)
        for d in range(1, top + 1):
            X = sweep_design(s[train], g, groups - 1, d)
            if np.linalg.matrix_rank(X) < X.shape[1]:
                error[d - 1] = np.inf
                continue
            beta, *_ = np.linalg.lstsq(X, u[train], rcond=None)
            powers = np.column_stack([s[test] ** k for k in range(1, d + 1)])
            r = u[test] - powers @ beta[groups - 1:]
            r -= r.mean(axis=0)
            error[d - 1] += (r ** 2).sum(axis=0)
    return np.argmin(error, axis=0) + 1
