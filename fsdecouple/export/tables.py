"""Hermite tables of the chi functions for an exported header (``--max-error``).

Each chi (eq. 4) is resampled on a uniform grid from the exact kernel sum
(eq. 10) and its derivative, turned into power-basis cubic Hermite coefficients
(the form of the model's own ChiSurrogate), and its error measured against the
kernel sum on knots, midpoints (where a Hermite interpolant's error peaks) and
``CHECKS_PER_INTERVAL`` points per interval.  Through eq. (11) an error e in
chi_ab is an error e / |k_aa| in force a.
"""

from __future__ import annotations

import numpy as np

from ..core.extrapolation import aligned_grid
from ..errors import FsdecoupleError
from .plan import ChiPlan, ExportPlan

CHECKS_PER_INTERVAL = 20  # check points per interval (knots, midpoints included)
MAX_INTERVALS = 1 << 14  # Hermite error falls as h^4: past this, double rounding dominates
TABLE_MARGIN = 0.25  # a table with no model table to follow covers the range +- 25 % of its span


def hermite(values: np.ndarray, slopes: np.ndarray, h: float) -> np.ndarray:
    """Power-basis coefficients c0..c3 per interval of the cubic Hermite interpolant.

    On interval i with s in [0, 1): ((c3 s + c2) s + c1) s + c0, the form the
    model's ChiSurrogate.coefficients() gives (tested to agree).
    """
    y0, y1, d0, d1 = values[:-1], values[1:], h * slopes[:-1], h * slopes[1:]
    return np.stack([y0, d0, 3.0 * (y1 - y0) - 2.0 * d0 - d1, 2.0 * (y0 - y1) + d0 + d1])


def chi_slope(cp: ChiPlan, u: np.ndarray) -> np.ndarray:
    """d chi / du [V/V] of the kernel sum (eq. 10) at ``u``, exactly (beyond the calibrated
    range of a tangent-extrapolating chi, its edge slope: :mod:`fsdecouple.core.extrapolation`)."""
    if hasattr(cp.exact, "slope"):  # the model's Chi: the slope of what it evaluates
        return cp.exact.slope(np.asarray(u, float))
    d = np.asarray(u, float)[:, None] / cp.in_scale - cp.sv[None, :]
    w = cp.coef * np.exp(-cp.gamma * d * d) * (-2.0 * cp.gamma * d)
    return w.sum(axis=1) * (cp.out_scale / cp.in_scale)


def table_value(coef: np.ndarray, lo: float, inv_step: float, u: np.ndarray) -> np.ndarray:
    """Table value at ``u`` (inside it), by the C's index rule and Horner order."""
    t = (u - lo) * inv_step
    i = t.astype(np.intp)
    s = t - i
    return ((coef[3, i] * s + coef[2, i]) * s + coef[1, i]) * s + coef[0, i]


def table_error(cp: ChiPlan, coef: np.ndarray) -> float:
    """max |table - kernel sum| [V] on knots, midpoints and 20 points per interval."""
    n = coef.shape[1]
    s = np.arange(2 * CHECKS_PER_INTERVAL + 1) / (2 * CHECKS_PER_INTERVAL)
    u = cp.lo + (cp.hi - cp.lo) * ((np.arange(n)[:, None] + s[None, :]) / n).ravel()
    inv = n / (cp.hi - cp.lo)
    t = (u - cp.lo) * inv
    u = u[(t >= 0) & (t < n)]  # as the C: a point whose index rounds to n goes the exact way
    return float(np.max(np.abs(table_value(coef, cp.lo, inv, u) - cp.exact(u))))


def resample(cp: ChiPlan, n: int) -> tuple[np.ndarray, float]:
    """Table of ``n`` intervals from the kernel sum and its slope, and its measured error."""
    knots = cp.lo + (cp.hi - cp.lo) * np.arange(n + 1) / n
    coef = hermite(cp.exact(knots), chi_slope(cp, knots), (cp.hi - cp.lo) / n)
    return coef, table_error(cp, coef)


def coarsest_tables(plan: ExportPlan, model, fraction: float, requested: float) -> None:
    """Per chi, the fewest intervals whose error keeps the force bound <= ``fraction``."""
    fs, k = plan.full_scale, np.abs(plan.k)
    # sensor-frame share: a rotated component i sums |R_ij| times the errors of components j
    if plan.rotation is not None:
        fraction *= float(np.min(fs / (np.abs(plan.rotation) @ fs)))
    for cp in plan.chis:
        c = cp.exact  # the model's Chi, cross or own-load
        a, b = c.input_range
        if c.surrogate is not None:
            cp.lo, cp.hi = float(c.surrogate.lo), float(c.surrogate.hi)
        else:
            span = max(b - a, 1e-3)
            cp.lo, cp.hi = a - TABLE_MARGIN * span, b + TABLE_MARGIN * span
        aligned = getattr(c, "edges", None) is not None and b > a

        def grid(m: int, cp=cp, a=a, b=b, aligned=aligned) -> int:
            # tangent extrapolation: m intervals over the range and whole ones beyond,
            # so its ends, where chi'' jumps, are knots (extrapolation.aligned_grid)
            if aligned:
                cp.lo, cp.hi, m = aligned_grid(a, b, m, TABLE_MARGIN)
            return m

        target = fraction * fs[cp.out] * k[cp.out] / plan.terms_per_output  # [V], eq. (11): / k_aa
        m, last = 1, np.inf
        while True:
            coef, err = resample(cp, grid(m))
            if err <= target:
                break
            if m >= MAX_INTERVALS or (m >= 64 and err > last / 4):  # h^4 would give /16
                raise FsdecoupleError(
                    f"--max-error {requested:g} is below what a table can reach: chi_{cp.out}{cp.inp} "
                    f"stops at {err / (fs[cp.out] * k[cp.out]):.3g} of full scale ({m} intervals)")
            m, last = 2 * m, err
        lo_m = m // 2  # bisect between the last failing and the first passing count
        while m - lo_m > 1:
            mid = (lo_m + m) // 2
            c_mid, e_mid = resample(cp, grid(mid))
            if e_mid <= target:
                m, coef, err = mid, c_mid, e_mid
            else:
                lo_m = mid
        grid(m)  # the kept table's interval
        cp.table, cp.table_error = coef, err


def table_bound(plan: ExportPlan) -> np.ndarray:
    """Force error bound per component from the tables' measured errors, / full scale."""
    d = np.zeros(plan.n)
    for c in plan.chis:
        if c.table is not None:
            d[c.out] += c.table_error / abs(plan.k[c.out])  # eq. (11)
    if plan.rotation is not None:
        d = np.abs(plan.rotation) @ d
    return d / plan.full_scale
