"""Coarser chi tables for an exported header (``--max-error``).

Each chi (eq. 4) is resampled on a uniform grid from the exact kernel sum (eq. 10)
and its derivative into a :class:`~fsdecouple.core.surrogate.ChiSurrogate`, the
model's own table form (one Hermite formula, one lookup), and its error measured
against the chi on the surrogate's check grid (knots, midpoints, where a Hermite
interpolant's error peaks, and ``CHECKS_PER_INTERVAL`` points per interval).
Through eq. (11) an error e in chi_ab is an error e / |k_aa| in force a.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..core.extrapolation import aligned_grid
from ..core.plan import Term
from ..core.surrogate import MARGIN, ChiSurrogate, knots, measured_error
from ..errors import FsdecoupleError
from .plan import ExportPlan

MAX_INTERVALS = 1 << 14  # Hermite error falls as h^4: past this, double rounding dominates


def resample(term: Term, n: int, lo: float | None = None, hi: float | None = None) -> ChiSurrogate:
    """The chi's table of ``n`` intervals on [lo, hi] (default: its current table's), from
    the exact chi and its slope at the knots, with its measured ``max_error``."""
    if lo is None:
        lo, hi = term.table.lo, term.table.hi
    x = knots(lo, hi, n)
    table = ChiSurrogate(float(lo), float(hi), term.chi(x), term.chi.slope(x), 0.0)
    return replace(table, max_error=measured_error(term.chi, table))


def coarsest_tables(plan: ExportPlan, fraction: float, requested: float) -> None:
    """Per chi, the fewest intervals whose error keeps the force bound <= ``fraction``."""
    fs, k = plan.full_scale, np.abs(plan.k)
    # sensor-frame share: a rotated component i sums |R_ij| times the errors of components j
    if plan.rotation is not None:
        fraction *= float(np.min(fs / (np.abs(plan.rotation) @ fs)))
    terms = []
    for term in plan.chis:
        c = term.chi  # the model's Chi, cross or own-load
        a, b = c.input_range
        if c.surrogate is not None:
            lo, hi = float(c.surrogate.lo), float(c.surrogate.hi)
        else:
            span = max(b - a, 1e-3)
            lo, hi = a - MARGIN * span, b + MARGIN * span
        aligned = getattr(c, "edges", None) is not None and b > a

        def grid(m: int, lo=lo, hi=hi, a=a, b=b, aligned=aligned) -> tuple[float, float, int]:
            # tangent extrapolation: m intervals over the range and whole ones beyond,
            # so its ends, where chi'' jumps, are knots (extrapolation.aligned_grid)
            return aligned_grid(a, b, m, MARGIN) if aligned else (lo, hi, m)

        def table(m: int, term=term, grid=grid) -> ChiSurrogate:
            lo_m, hi_m, count = grid(m)
            return resample(term, count, lo_m, hi_m)

        target = fraction * fs[term.out] * k[term.out] / plan.terms_per_output  # [V], eq. (11)
        m, last = 1, np.inf
        while True:
            best = table(m)
            if best.max_error <= target:
                break
            if m >= MAX_INTERVALS or (m >= 64 and best.max_error > last / 4):  # h^4 would give /16
                raise FsdecoupleError(
                    f"--max-error {requested:g} is below what a table can reach: chi_{term.out}"
                    f"{term.inp} stops at {best.max_error / (fs[term.out] * k[term.out]):.3g} of "
                    f"full scale ({m} intervals)")
            m, last = 2 * m, best.max_error
        lo_m = m // 2  # bisect between the last failing and the first passing count
        while m - lo_m > 1:
            mid = (lo_m + m) // 2
            t_mid = table(mid)
            if t_mid.max_error <= target:
                m, best = mid, t_mid
            else:
                lo_m = mid
        terms.append(replace(term, table=best))
    plan.plan = plan.plan.with_terms(terms)


def table_bound(plan: ExportPlan) -> np.ndarray:
    """Force error bound per component from the tables' measured errors, / full scale."""
    d = np.zeros(plan.n)
    for c in plan.chis:
        if c.table is not None:
            d[c.out] += c.table.max_error / abs(plan.k[c.out])  # eq. (11)
    if plan.rotation is not None:
        d = np.abs(plan.rotation) @ d
    return d / plan.full_scale
