"""What a chi is outside its calibrated input range: ``extrapolation: tangent|kernel``.

A corrected coupling function chi_ab (eq. 4) is fitted on the prime outputs u_b
of the b sweeps, ``input_range = [lo, hi]``.  Beyond it the eps-SVR's kernel sum
(eq. 10) decays to its bias -rho within a few kernel widths, so chi collapses
exactly where a load beyond full scale needs it most.

* ``kernel``: the kernel sum everywhere, as fitted (the behaviour of every model
  file written before this option, which read as ``kernel``);
* ``tangent`` (the default of new fits): the kernel sum inside [lo, hi] and its
  tangent at the nearer edge outside,

      chi(u) = chi(lo) + chi'(lo) (u - lo)   for u < lo,
      chi(u) = chi(hi) + chi'(hi) (u - hi)   for u > hi,

  continuous in value and slope (chi' is the kernel sum's analytic derivative,
  :func:`fsdecouple.core.kernel.rbf_sum_slope`, times output_scale / input_scale).

Every path evaluates the same function: the exact path through
:class:`fsdecouple.core.model.Chi`, the table path through tables built from it on a
grid with knots at lo and hi (:func:`table_interval`: a cubic Hermite table
then reproduces the straight continuation exactly, so the evaluators need no
branch of their own), and the C export through the same constants
(:func:`edges`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

# The tables of a tangent model start on MIN_INTERVALS = 256 intervals (surrogate.py),
# EDGE_KNOT of them before lo and as many after hi, so lo and hi are knots of every
# level of the refinement (which doubles the count): the table reaches
# EDGE_KNOT / (256 - 2 EDGE_KNOT) = 25.3 % of the span past each edge, like the
# kernel tables' surrogate.MARGIN of 25 %.
TABLE_INTERVALS, EDGE_KNOT = 256, 43



class Edges(NamedTuple):
    """A chi's calibrated input range and its value [V] and slope [V/V] at both ends."""

    lo: float
    hi: float
    value_lo: float
    slope_lo: float
    value_hi: float
    slope_hi: float


def edges(lo: float, hi: float, value, slope) -> Edges | None:
    """The tangents at ``lo`` and ``hi`` from callables ``value(u)`` and ``slope(u)``.

    None when the range is not finite (a chi built without one): no continuation.
    """
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return None
    u = np.array([lo, hi])
    v, s = (np.asarray(f(u), dtype=float) for f in (value, slope))
    return Edges(float(lo), float(hi), float(v[0]), float(s[0]), float(v[1]), float(s[1]))


def continue_values(u: np.ndarray, inside: np.ndarray, e: Edges) -> np.ndarray:
    """``inside`` (the kernel sum at u) where lo <= u <= hi, the tangent beyond.

    The arithmetic is the C export's, ``value + slope * (u - edge)``.  NaN stays
    NaN (it compares false on both sides).
    """
    u = np.asarray(u, dtype=float)
    with np.errstate(invalid="ignore", over="ignore"):
        out = np.where(u < e.lo, e.value_lo + e.slope_lo * (u - e.lo), inside)
        return np.where(u > e.hi, e.value_hi + e.slope_hi * (u - e.hi), out)


def continue_slopes(u: np.ndarray, inside: np.ndarray, e: Edges) -> np.ndarray:
    """d chi / du: ``inside`` (the kernel sum's slope) in the range, the edge slope beyond."""
    u = np.asarray(u, dtype=float)
    return np.where(u < e.lo, e.slope_lo, np.where(u > e.hi, e.slope_hi, inside))


def table_interval(lo: float, hi: float) -> tuple[float, float]:
    """The interval of a tangent model's tables: lo and hi fall on knots (see EDGE_KNOT).

    A degenerate range (hi <= lo) takes the kernel tables' interval.
    """
    from .surrogate import table_interval as kernel_interval

    if not hi > lo:
        return kernel_interval(lo, hi)
    pad = (hi - lo) * EDGE_KNOT / (TABLE_INTERVALS - 2 * EDGE_KNOT)
    lo, hi = lo - pad, hi + pad
    # the table's own upper end indexes to t = intervals exactly, so it lies outside the
    # half-open table at every level (2^k intervals scale t exactly): an ulp at most
    for _ in range(64):
        if (hi - lo) * (TABLE_INTERVALS / (hi - lo)) >= TABLE_INTERVALS:
            break
        hi = float(np.nextafter(hi, np.inf))
    return lo, hi


def aligned_grid(lo: float, hi: float, inner: int, margin: float) -> tuple[float, float, int]:
    """A uniform grid of ``inner`` intervals over [lo, hi] plus ceil(margin * inner) each side.

    ``(table lo, table hi, interval count)``: lo and hi are knots, so a Hermite
    table of a tangent chi has no kink inside an interval (export ``--max-error``).
    """
    pad = math.ceil(margin * inner)
    h = (hi - lo) / inner
    return lo - pad * h, hi + pad * h, inner + 2 * pad
