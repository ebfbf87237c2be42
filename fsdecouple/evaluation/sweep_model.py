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
from eq. (11)'s forces (:meth:`SweepModel.forces`).

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
interval's centre there is eq. (11)'s refined forces (:meth:`SweepModel.inside`).
"""

from __future__ import annotations

import itertools
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from ..axes import Layout
from ..core.model import RANGE_MARGIN
from ..data.zero import sweep_design
from ..errors import InputError

if TYPE_CHECKING:  # apply reads the model, never pandas (tests/core/test_fast.py)
    import pandas as pd

MAX_DEGREE = 7  # of a g_ab; 9 and 12 measured alike (docs/design/intervals.md)
NEWTON_STEPS = 30
RANK_TOLERANCE = 1e-12  # of R's largest diagonal: a design column that is no new direction
NEWTON_TOLERANCE = 1e-10  # of the largest calibrated load: a row has settled (the noise: ~1e-4)


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
        levels = min((np.unique(f[group == g]).size for g in range(groups)), default=0)
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


class SweepModel:
    """The stored model as polynomials in each s_b = f_b / L_b, per output a and load b,
    coefficients of s^0, s^1, ... (padded to one degree): g_ab, its derivative and the
    model's variance x(s)' C_ab x(s) (a polynomial of twice the degree)."""

    def __init__(self, doc: dict[str, Any]):
        self.peak = np.asarray(doc["peak"], dtype=float)
        self.span = np.asarray(doc["span"], dtype=float).reshape(-1, 2)
        n = self.peak.size
        d = max(len(c) for row in doc["shape"] for c in row)
        self.g = np.zeros((n, n, d + 1))  # [a, b, power]: g_ab(0) = 0
        self.quad = np.zeros((n, n, 2 * d + 1))  # x' C x = sum_{k,l} C_kl s^(k+l)
        for b in range(n):
            for a in range(n):
                beta = np.asarray(doc["shape"][b][a], dtype=float)
                cov = np.asarray(doc["covariance"][b][a], dtype=float).reshape(beta.size, beta.size)
                self.g[a, b, 1:beta.size + 1] = beta
                k = np.arange(1, beta.size + 1)
                np.add.at(self.quad[a, b], (k[:, None] + k[None, :]).ravel(), cov.ravel())
        powers = np.arange(1, d + 1)
        self.slope = self.g[..., 1:] * powers / self.peak[None, :, None]  # dg_ab/df_b
        self.noise = np.asarray(doc["noise_variance"], dtype=float)

    def inside(self, f: np.ndarray) -> np.ndarray:
        """Rows (of forces ``f``, (n, N)) whose every load lies in the calibrated span
        widened by ``RANGE_MARGIN`` of it (the margin ``apply``'s status ``extrapolated``
        gives the outputs): beyond it the polynomials extrapolate, and their centre is
        not used."""
        margin = RANGE_MARGIN * (self.span[:, 1] - self.span[:, 0])
        with np.errstate(invalid="ignore"):
            return np.all((f >= self.span[:, 0] - margin) & (f <= self.span[:, 1] + margin), axis=1)

    def largest_ratio(self) -> float:
        """rho = sqrt(model's variance / reading's) at its largest where every load is at
        an end of its span or 0 (3^N rows): the range of the half-widths' grid, the same
        for every block of a log."""
        corners = np.array(list(itertools.product(*[(lo, 0.0, hi) for lo, hi in self.span])))
        reading, model = self.variances(corners)
        with np.errstate(all="ignore"):
            rho = np.sqrt(model / reading)
        return float(np.max(rho[np.isfinite(rho)], initial=0.0))

    def outputs(self, f: np.ndarray) -> np.ndarray:
        """g(f) = sum_b g_ab(f_b), shape (n, N) [output unit]."""
        return _sum_of_polynomials(self.g, f / self.peak)

    def jacobian(self, f: np.ndarray) -> np.ndarray:
        """J_ab = dg_a/df_b at ``f``, shape (n, N, N)."""
        x = _powers(f / self.peak, self.slope.shape[2] - 1)
        return np.stack([x[:, b] @ self.slope[:, b].T for b in range(self.peak.size)], axis=2)

    def forces(self, u: np.ndarray, start: np.ndarray) -> np.ndarray:
        """The forces whose outputs are ``u`` (zero-corrected, (n, N)), from ``start``;
        NaN where a row does not settle.  Newton's method with the Jacobian of the start
        kept (the chord method: ``start`` is eq. (11)'s refined forces, within the noise
        of the solution, where J hardly moves), one inverse a row instead of one a step."""
        f = np.where(np.isfinite(start), start, 0.0)
        settled = np.zeros(len(u), dtype=bool)
        tol = NEWTON_TOLERANCE * self.peak.max()
        with np.errstate(all="ignore"):
            inv, ok = _inverse(self.jacobian(f))
            active = np.flatnonzero(np.isfinite(u).all(axis=1) & ok)
            for _ in range(NEWTON_STEPS):
                if not active.size:
                    break
                step = np.einsum("nab,nb->na", inv[active], u[active] - self.outputs(f[active]))
                f[active] += step
                small = np.abs(step).max(axis=1) <= tol
                settled[active[small]] = True
                active = active[~small & np.isfinite(f[active]).all(axis=1)]
        return np.where(settled[:, None], f, np.nan)

    def variances(self, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """At forces ``f`` (n, N): the variance of each force's error from the reading
        and from the model, each (n, N) [load unit^2]; NaN where J is singular."""
        with np.errstate(all="ignore"):
            x = np.nan_to_num(f)
            model = self.noise * _sum_of_polynomials(self.quad, x / self.peak)
            inv, ok = _inverse(self.jacobian(x))
            sq = inv ** 2
            reading = sq @ self.noise
            shared = np.einsum("nac,nc->na", sq, model)
        bad = ~ok | ~np.isfinite(f).all(axis=1)
        reading[bad] = np.nan
        shared[bad] = np.nan
        return reading, shared


def _powers(s: np.ndarray, degree: int) -> np.ndarray:
    """s^0 .. s^degree of every load, shape (n, B, degree + 1)."""
    out = np.empty((*s.shape, degree + 1))
    out[..., 0] = 1.0
    for k in range(1, degree + 1):
        np.multiply(out[..., k - 1], s, out=out[..., k])
    return out


def _sum_of_polynomials(c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """sum_b sum_k c[a, b, k] s_b^k for every row, shape (n, A): one product of the
    powers (n, B (d + 1)) with the coefficients."""
    x = _powers(s, c.shape[2] - 1)
    return x.reshape(len(s), -1) @ c.reshape(c.shape[0], -1).T


def _inverse(jac: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """J^-1 of every row, and which rows' J is invertible: singular where |det J| is
    below 1e-12 of the product of its rows' norms (those rows: the identity's).  Three
    components: the adjugate, whose columns are the rows' cross products."""
    n = jac.shape[-1]
    finite = np.isfinite(jac).all(axis=(1, 2))
    safe = np.where(finite[:, None, None], jac, np.eye(n))
    scale = np.prod(np.linalg.norm(safe, axis=2), axis=1)
    if n == 3:
        r0, r1, r2 = safe[:, 0], safe[:, 1], safe[:, 2]
        adj = np.stack([np.cross(r1, r2), np.cross(r2, r0), np.cross(r0, r1)], axis=2)
        det = np.einsum("ni,ni->n", r0, adj[:, :, 0])
        ok = finite & (np.abs(det) > 1e-12 * scale)
        inv = adj / np.where(ok, det, 1.0)[:, None, None]
        inv[~ok] = np.eye(n)
        return inv, ok
    ok = finite & (np.abs(np.linalg.det(safe)) > 1e-12 * scale)
    safe[~ok] = np.eye(n)
    return np.linalg.inv(safe), ok


def check_sweep_model(doc: Any, labels) -> None:
    """Refuse a stored sweep model a fit cannot have written (None: there is none):
    per component a peak > 0, per component and output a shape of 1 to
    ``MAX_DEGREE`` finite numbers and its covariance, symmetric and positive
    semi-definite, and per output a noise variance > 0."""
    if doc is None:
        return
    n = len(labels)

    def damaged(what: str, value, expected: str) -> InputError:
        return InputError(f"intervals: the model file's interval data are damaged (least_squares "
                          f"{what} is {value!r}, expected {expected}); refit the model",
                          argument="interval")

    if not isinstance(doc, dict):
        raise damaged("", doc, "the sweep model's fields")
    for key in ("peak", "noise_variance"):
        v = doc.get(key)
        if not (isinstance(v, list) and len(v) == n and all(_number(x) and x > 0 for x in v)):
            raise damaged(key, v, f"{n} finite numbers > 0")
    v = doc.get("span")
    if not (isinstance(v, list) and len(v) == n
            and all(isinstance(r, list) and len(r) == 2 and all(_number(x) for x in r) and r[0] < r[1]
                    for r in v)):
        raise damaged("span", v, f"{n} pairs of finite loads, the lower first")
    for key in ("shape", "covariance"):
        v = doc.get(key)
        if not (isinstance(v, list) and len(v) == n and all(isinstance(r, list) and len(r) == n for r in v)):
            raise damaged(key, v, f"{n} x {n} entries")
    for b, axis in enumerate(labels):
        for a in range(n):
            beta, cov = doc["shape"][b][a], doc["covariance"][b][a]
            where = f"{{load {axis}, output {a + 1}}}"
            if not (isinstance(beta, list) and 1 <= len(beta) <= MAX_DEGREE
                    and all(_number(x) for x in beta)):
                raise damaged(f"shape {where}", beta, f"1 to {MAX_DEGREE} finite numbers")
            k = len(beta)
            if not (isinstance(cov, list) and len(cov) == k
                    and all(isinstance(r, list) and len(r) == k and all(_number(x) for x in r)
                            for r in cov)):
                raise damaged(f"covariance {where}", "...", f"{k} x {k} finite numbers")
            c = np.asarray(cov, dtype=float)
            # as fitted, R^-1 R^-T: symmetric to the bit and positive semi-definite
            size = np.abs(c).max(initial=0.0)
            if not (np.abs(c - c.T).max(initial=0.0) <= 1e-6 * size
                    and np.linalg.eigvalsh(c).min() >= -1e-6 * size):
                raise damaged(f"covariance {where}", "...",
                              "a symmetric positive semi-definite matrix")


def _number(x) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)
