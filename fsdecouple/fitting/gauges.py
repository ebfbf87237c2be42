"""More outputs than components (M > N, issue 22): a forward model for each output,
decoupled in the least-squares sense.

A six-axis sensor with eight strain gauges has no prime output per component: every
gauge responds to several loads, so eq. (2)'s omega_a, one output for one load, does
not exist.  Its generalisation is the linear forward model of each output j,

    u_j = sum_a K_ja f_a                                       (eq. 2, generalised)

K (M x N) fitted by least squares through the origin (the rows are zero-corrected),
with the corrected coupling functions of eq. (4) added to each output, as the joint
fit of rig rows does (:mod:`fsdecouple.fitting.joint`):

    u_j = sum_a K_ja f_a + sum_b chi_jb(v_b),    v = P u,  P = K^+     (eqs. 2, 4)

v (N) is the least-squares solution of the linear model, in load units: a function of
the measured outputs, as eq. (4)'s chi are, so decoupling needs no inversion of a
chi.  Each chi_jb is an epsilon-SVR (eq. 10, Table 2's kernel width, C and epsilon as
:func:`fsdecouple.fitting.joint.joint_svr` sets them for output j), fitted by
backfitting on the partial residual u_j - K_j f - sum_{c != b} chi_jc(v_c) with K held
at its least-squares value (so that v stays P u).  Decoupling solves the M equations
in the least-squares sense (eq. 11 generalised):

    f = K^+ [u - chi(v)] = v - sum_b (K^+ chi_.b)(v_b),                 (eq. 11)

exactly, because K is fixed.  Each (K^+ chi_.b)_a is a sum of M kernel sums of one
input v_b with one kernel width: one kernel sum over their joined support vectors.  So
the fitted model *is* the coupling error model of eq. (11) on the N outputs v = P u,
with k_a = 1 (load unit per load unit), N(N - 1) cross chi and an own-load chi per
component: its surrogate tables, refinement and tangent extrapolation are the N = M
model's, after one matrix product.  The baseline is the N x M least-squares
calibration matrix f = C u (``fit --method linear|auto``).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from .joint import CONVERGED, ITERATIONS, joint_svr

# The linear forward model K must separate the loads: its condition number (largest over
# smallest singular value, in full-scale units) above this and P = K^+ amplifies noise
# by as much; a rig whose gauges cannot tell two loads apart is refused by name.
MAX_CONDITION = 1e6
# libsvm's stopping tolerance in the normalised units the chi are fitted in (fractions of
# each output's full scale): Table 2's epsilon as a fraction of full scale, as noise.py.
SOLVE_FRACTION = 1e-4


def forward_matrix(f: np.ndarray, u: np.ndarray) -> np.ndarray:
    """K (M, N): the least-squares linear forward model u ~ K f through the origin (eq. 2)."""
    coef, *_ = np.linalg.lstsq(np.asarray(f, dtype=float), np.asarray(u, dtype=float),
                               rcond=None)
    return np.ascontiguousarray(coef.T)


def projection(f: np.ndarray, u: np.ndarray, full_scale, outputs, loads,
               source: str) -> tuple[np.ndarray, np.ndarray]:
    """(K, P): the forward model and its pseudo-inverse P = K^+ (N, M), checked.

    Refuses a K whose columns (one per load, in full-scale units) the outputs cannot
    tell apart, naming the loads.
    """
    k = forward_matrix(f, u)
    fs = np.asarray(full_scale, dtype=float)
    scaled = k * fs / np.maximum(np.abs(k * fs).max(axis=1, keepdims=True), 1e-300)
    _, sv, vt = np.linalg.svd(scaled, full_matrices=False)
    if not (np.isfinite(sv).all() and sv[-1] > sv[0] / MAX_CONDITION):
        v = vt[-1]
        tied = [loads[a] for a in np.flatnonzero(np.abs(v) > 0.1 * np.abs(v).max())]
        raise InputError(f"{source}: outputs {', '.join(outputs)} cannot separate loads "
                         f"{' and '.join(tied)} (the linear forward model is rank-deficient); "
                         "check the output columns")
    return k, np.linalg.pinv(k)


def gauge_scale(k: np.ndarray, full_scale) -> np.ndarray:
    """Each output's full-scale output (M,): its largest response to one full-scale load."""
    return np.abs(k * np.asarray(full_scale, dtype=float)).max(axis=1)


def backfit_output(residual: np.ndarray, x: np.ndarray, fit_chi, *, iterations: int = ITERATIONS,
                   converged: float = CONVERGED) -> list:
    """chi_jb(x_b) for b = 0 .. N - 1 of one output by backfitting, normalised units.

    ``residual``: u_j - K_j f (n,), what the chi sum must explain; ``x``: v / F_FS (n, N).
    """
    n = x.shape[1]
    part = [np.zeros(len(x)) for _ in range(n)]
    chi: list = [None] * n
    for _ in range(iterations):
        moved = 0.0
        for b in range(n):
            r = residual - sum(part[c] for c in range(n) if c != b)
            chi[b] = fit_chi(x[:, b], r)
            new = chi[b](x[:, b])
            moved = max(moved, float(np.abs(new - part[b]).max()))
            part[b] = new
        if moved <= converged:
            break
    return chi


def fit_forward(f: np.ndarray, u: np.ndarray, full_scale, p: np.ndarray, k: np.ndarray, svr,
                fit_svr, map_=map, noise=None) -> tuple[np.ndarray, dict[tuple[int, int], tuple], list]:
    """The chi of every output, merged by eq. (11): (v, {(a, b): (gamma, sv, coef, rho)},
    per-output chi).

    Merged in normalised units: chi'_ab(v_b) = F_FS,a (sum_i coef_i exp(-gamma (v_b / F_FS,b
    - sv_i)^2) - rho), the a-th row of K^+ chi_.b.  Per output j, chi_jb of v_b / F_FS,b in
    units of output j's full-scale output (:func:`gauge_scale`), as fitted.  ``map_``: a
    pool's map, for threads; ``noise``: each output's sigma from a pose log, if measured.
    """
    fs = np.asarray(full_scale, dtype=float)
    v = np.asarray(u, dtype=float) @ p.T
    fn, x = f / fs, v / fs
    ufs = gauge_scale(k, fs)
    un = u / ufs
    kn = k * fs / ufs[:, None]

    def one(j: int) -> list:
        s = joint_svr(svr, fn, un, j, None if noise is None else float(noise[j] / ufs[j]))
        return backfit_output(un[:, j] - fn @ kn[j], x, lambda xb, y: _Svr(fit_svr(xb, y, s)))

    per_output = list(map_(one, range(u.shape[1])))
    merged = {}
    n = f.shape[1]
    for a in range(n):
        w = p[a] * ufs / fs[a]  # weight of output j's chi in component a
        for b in range(n):
            fitted = [per_output[j][b] for j in range(u.shape[1])]
            gamma = {c.gamma for c in fitted}
            if len(gamma) != 1:
                raise ValueError("the chi of one input share Table 2's kernel width")
            sv = np.concatenate([c.support_vectors for c in fitted])
            coef = np.concatenate([wj * c.dual_coef for wj, c in zip(w, fitted, strict=True)])
            rho = float(sum(wj * c.rho for wj, c in zip(w, fitted, strict=True)))
            merged[(a, b)] = (gamma.pop(), sv, coef, rho)
    return v, merged, per_output


class _Svr:
    """A fitted SVR (svr.py) as a callable of normalised inputs, while backfitting."""

    def __init__(self, s):
        self.gamma, self.support_vectors, self.dual_coef, self.rho = (
            float(s.gamma), np.asarray(s.support_vectors, float), np.asarray(s.dual_coef, float),
            float(s.rho))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        d = np.subtract.outer(np.asarray(x, dtype=float), self.support_vectors)
        return np.exp(-self.gamma * d * d) @ self.dual_coef - self.rho


def projected(points, p: np.ndarray, layout):
    """Calibration points with the M outputs replaced by v = P u, named ``<label>_ls`` (the
    least-squares load of each component), and their layout: for the checks that read one
    output per component (gross errors, fitting/outliers.py)."""
    from ..axes import Layout

    virtual = Layout(layout.labels, layout.loads, tuple(f"{a}_ls" for a in layout.labels))
    v = points[list(layout.outputs)].to_numpy(dtype=float) @ p.T
    out = points.drop(columns=list(layout.outputs))
    for a, name in enumerate(virtual.outputs):
        out[name] = v[:, a]
    return out, virtual
