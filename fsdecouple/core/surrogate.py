"""Piecewise-cubic surrogates of the chi functions, verified against the kernel sum.

Each chi (eq. 4) is a smooth function of one prime voltage, but its exact value is
a sum of ~100 Gaussians whose dual coefficients reach C = 1000 and cancel to a
result of a few 10 mV.  A cubic Hermite interpolant on a uniform grid (values and
exact slopes of the kernel sum at the knots) reproduces it to ~1e-11 V with a few
hundred intervals and costs four table look-ups and a Horner step per input.

The tables are built after the fit.  The grid is refined (interval count doubled,
old knots reused) until the error measured on a dense check grid is at most
:data:`TOLERANCE`, or doubling stops helping, or a budget of kernel evaluations
is spent (see :func:`build_pair`).  The error measured on the dense check grid
of the table kept is stored in the model file beside it, so a reader knows what
the fast path promises, and a table that missed is left to the exact path.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property
from typing import Any

import numpy as np

KIND = "hermite3-uniform"
# Target for the measured max |surrogate - kernel sum| per chi [V]: a tenth of
# the 1e-9 V promise, so that the two chi of one output stay far inside it.
TOLERANCE = 1e-10
CHECKS_PER_INTERVAL = 20  # dense check points per interval, plus knots and midpoints
MIN_INTERVALS, MAX_INTERVALS = 256, 1 << 17
# Refinement has stalled for a chi when doubling cut its error by less than this
# factor while the error is already near the kernel sum's rounding floor.  A
# Hermite cubic's error is O(h^4), so in its asymptotic regime each doubling cuts
# it ~16x; under 2x, three of the four expected bits are lost to noise that finer
# tables cannot remove (rounding in the knot values, slopes and the reference).
STALL_FACTOR = 2.0
# "Near the floor" means within FLOOR_FACTOR * eps * |output_scale| * sum|dual_coef|,
# the scale of the rounding in a kernel sum whose terms cancel (the floors
# measured on the sample data are 0.2-0.35 of eps * sum|dual_coef|).  Without this
# condition a coarse grid that does not yet resolve the Gaussians (error flat for
# a doubling or two, as on millivolt data with volt-sized kernels) would count as
# stalled and stop a table that finer grids would make usable.
FLOOR_FACTOR = 10.0
# Kernel terms (points x support vectors, values and slopes alike) that building
# the tables of one input axis may spend, the final dense check included: about
# 0.3-0.5 s at the ~5-10 ns a term measured here, and room for a dense check of
# ~5000 intervals with 240 support vectors.  The sample data's tables cost ~3e6;
# a table that needs more is a symptom of unscaled inputs (fit warns about the
# kernel widths), and unscaled millivolt data once spent 78 s here.
KERNEL_BUDGET = 5e7
# The table covers the calibrated range widened by this fraction of its span on
# each side (task data after a tare may stray a little beyond the calibration).
MARGIN = 0.25


@dataclass(frozen=True)
class ChiSurrogate:
    """Cubic Hermite interpolant of one chi on ``intervals`` equal steps of [lo, hi].

    Attributes
    ----------
    lo, hi : float
        Interval covered [V]; inputs outside it use the exact kernel sum.
    values : ndarray, shape (intervals + 1,)
        chi at the knots [V] (exact kernel sum).
    slopes : ndarray, shape (intervals + 1,)
        dchi/du at the knots [V/V] (exact derivative of the kernel sum).
    max_error : float
        Largest |surrogate - kernel sum| found on the check grid at fit time [V].
    checks_per_interval : int
        Check points per interval used to measure ``max_error``.
    """

    lo: float
    hi: float
    values: np.ndarray
    slopes: np.ndarray
    max_error: float
    checks_per_interval: int = CHECKS_PER_INTERVAL

    @property
    def intervals(self) -> int:
        return self.values.size - 1

    @property
    def inv_step(self) -> float:
        """Intervals per volt; the same expression everywhere so indices agree."""
        return self.intervals / (self.hi - self.lo)

    def coefficients(self) -> np.ndarray:
        """Power-basis coefficients c0..c3 per interval, shape (4, intervals) (:func:`hermite`).

        On interval i, with s = (u - lo) * inv_step - i in [0, 1):
        chi(u) ~ ((c3 s + c2) s + c1) s + c0.
        """
        return self._coefficients

    @cached_property
    def _coefficients(self) -> np.ndarray:
        return hermite(self.values, self.slopes, (self.hi - self.lo) / self.intervals)

    def covers(self, u: np.ndarray) -> np.ndarray:
        """Where the table serves ``u``: 0 <= (u - lo) * inv_step < intervals.

        The evaluators use this very expression (:func:`cell`), so a voltage a hair
        below ``hi`` whose index rounds up to ``intervals`` is left to the exact path
        here too.
        """
        return cell(np.asarray(u, dtype=float), self.lo, self.inv_step, self.intervals)[2]

    def __call__(self, u: np.ndarray, dtype=np.float64) -> np.ndarray:
        """Surrogate chi [V] at prime voltages ``u`` [V] the table covers; NaN elsewhere.

        ``dtype``: the arithmetic's precision (float32: as an exported float header).
        """
        u = np.asarray(u, dtype=dtype)
        c = self.coefficients().astype(dtype)
        i, s, inside = cell(u, dtype(self.lo), dtype(self.inv_step), self.intervals)
        out = horner(c[0, i], c[1, i], c[2, i], c[3, i], s)
        return np.where(inside, out, np.nan)

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": KIND,
            "interval": [self.lo, self.hi],
            "intervals": self.intervals,
            "values": self.values.tolist(),
            "slopes": self.slopes.tolist(),
            "max_error": self.max_error,
            "checks_per_interval": self.checks_per_interval,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ChiSurrogate:
        if d["kind"] != KIND:
            raise ValueError(f"unknown surrogate kind {d['kind']!r}")
        lo, hi = (float(v) for v in d["interval"])
        values = np.asarray(d["values"], dtype=float)
        slopes = np.asarray(d["slopes"], dtype=float)
        n = int(d["intervals"])
        if values.shape != (n + 1,) or slopes.shape != (n + 1,) or not hi > lo:
            raise ValueError("surrogate table does not match its interval count")
        return cls(lo, hi, values, slopes, float(d["max_error"]), int(d["checks_per_interval"]))


def hermite(values: np.ndarray, slopes: np.ndarray, h: float) -> np.ndarray:
    """Power-basis coefficients c0..c3 (4, n) of the cubic Hermite interpolant of ``values``
    and ``slopes`` at n + 1 knots a step ``h`` apart: the one definition of a table."""
    y0, y1 = values[:-1], values[1:]
    d0, d1 = h * slopes[:-1], h * slopes[1:]
    return np.stack([y0, d0, 3.0 * (y1 - y0) - 2.0 * d0 - d1, 2.0 * (y0 - y1) + d0 + d1])


def horner(c0, c1, c2, c3, s):
    """A table's cubic at offset ``s`` in [0, 1) of its interval: ((c3 s + c2) s + c1) s + c0.

    Scalars (the one-vector path; compiled by numba for the table kernel) or arrays; no
    fused multiply-add anywhere, so every evaluator rounds alike.
    """
    return ((c3 * s + c2) * s + c1) * s + c0


def cell(x: np.ndarray, lo, inv_step, intervals: int):
    """``(interval i, offset s, inside)`` of ``x`` in a table: t = (x - lo) * inv_step,
    i = int(t), s = t - i; inside where 0 <= t < intervals (False for NaN).  Outside,
    i = 0, for the caller to replace."""
    t = (x - lo) * inv_step
    with np.errstate(invalid="ignore"):
        inside = (t >= 0) & (t < intervals)
    i = np.where(inside, t, 0).astype(np.intp)
    return i, t - i.astype(t.dtype), inside


def check_points(lo: float, hi: float, intervals: int, per_interval: int) -> np.ndarray:
    """Knots, midpoints and ``per_interval`` evenly spread points inside each interval."""
    sub = np.arange(2 * per_interval + 1) / (2 * per_interval)  # includes 0 and 1/2
    knots = np.arange(intervals) / intervals
    x = lo + (hi - lo) * (knots[:, None] + sub[None, :] / intervals).ravel()
    return np.append(x, hi)


def knots(lo: float, hi: float, n: int, start: int = 0, step: int = 1) -> np.ndarray:
    """Knots ``lo + (hi - lo) * i / n`` of the n-interval grid, i = start, start + step, ... <= n.

    Refinement reuses knots: the knots of n intervals are bit for bit the even
    knots of 2n.  Rounded, (hi - lo) * (2i) is 2 fl((hi - lo) * i), because
    scaling by 2 is exact (no overflow or underflow at these sizes) and i < 2^53
    converts exactly; so fl(2 fl((hi - lo) i) / (2n)) = fl(fl((hi - lo) i) / n),
    the same real quotient rounded once, and adding lo gives the same double.
    Only the odd knots of 2n, the midpoints of n, are new.
    """
    return lo + (hi - lo) * np.arange(start, n + 1, step) / n


def _slope_fn(c):
    """The slope of what a model's Chi evaluates (its tangents too: extrapolation.py)."""
    return c.slope


def _max_error(name: str, table: ChiSurrogate, x: np.ndarray, exact: np.ndarray) -> float:
    inside = table.covers(x)  # hi, and any point whose index rounds to it, go the exact path
    err = float(np.max(np.abs(table(x[inside]) - exact[inside])))
    if not np.isfinite(err):
        raise FloatingPointError(f"chi_{name}: surrogate error is {err}")
    return err


def measured_error(chi, table: ChiSurrogate) -> float:
    """Largest |table - chi| on the table's full check grid [V]: what the model file records."""
    x = check_points(table.lo, table.hi, table.intervals, table.checks_per_interval)
    return _max_error(chi.name, table, x, chi(x))


# Kernel terms (points x support vectors) that verifying one table at load may
# spend: ~5 ms, so loading a model stays fast however large its tables.
LOAD_CHECK_BUDGET = 1e6
LOAD_CHECK_MIN_POINTS = 16


def spot_check(chi, table: ChiSurrogate) -> tuple[float, float]:
    """``(largest error, where)`` of a table against its chi: a model file's check at load.

    On each interval checked, the knot values and slopes at both ends against chi and
    chi' (which fix the interval's cubic: a table is the Hermite interpolant of chi, so
    no edit of values and slopes can hide between check points), and the midpoint
    against chi (the interpolation error, measured on the check grid at fit).  A slope
    error d is counted as the largest value error it makes inside its intervals,
    |d| h max|H10| = 4 |d| h / 27 on a step h.  Every interval when the budget
    (:data:`LOAD_CHECK_BUDGET`) allows, else at least :data:`LOAD_CHECK_MIN_POINTS`
    spread evenly over the table.
    """
    n = table.intervals
    per_interval = 3 * max(1, chi.support_vectors.size)  # a midpoint, a knot's value and slope
    count = min(n, max(LOAD_CHECK_MIN_POINTS, int(LOAD_CHECK_BUDGET // per_interval)))
    i = np.unique(np.linspace(0, n - 1, count).round().astype(np.intp))
    # check_points' expression for the midpoints (sub = 1/2), knots' for the knots, so
    # the same doubles as the fit's
    x = table.lo + (table.hi - table.lo) * (i / n + 0.5 / n)
    k = np.unique(np.concatenate([i, i + 1]))
    xk = table.lo + (table.hi - table.lo) * k / n
    h = (table.hi - table.lo) / n
    with np.errstate(all="ignore"):
        err = np.concatenate([np.abs(table(x) - chi(x)),
                              np.abs(table.values[k] - chi(xk)),
                              np.abs(table.slopes[k] - _slope_fn(chi)(xk)) * (4 * h / 27)])
    err = np.where(np.isnan(err), np.inf, err)
    worst = int(np.argmax(err))
    return float(err[worst]), float(np.concatenate([x, xk, xk])[worst])


def _interleave(even: np.ndarray, odd: np.ndarray) -> np.ndarray:
    out = np.empty(even.size + odd.size)
    out[::2], out[1::2] = even, odd
    return out


def build_pair(chis, lo: float, hi: float, tolerance: float = TOLERANCE,
               budget: float = KERNEL_BUDGET) -> list[ChiSurrogate]:
    """Surrogates of the chi sharing one input axis, on one common grid of [lo, hi].

    The interval count doubles from :data:`MIN_INTERVALS` until every chi meets
    ``tolerance`` on the full check grid, or refining stops helping (every chi
    either meets it or has stalled at the kernel sum's rounding floor, see
    :data:`STALL_FACTOR`), or the next level would pass ``budget`` kernel terms
    or :data:`MAX_INTERVALS`; then the best level so far is kept.  Either way the
    recorded ``max_error`` is measured on the full check grid of the table
    returned, so a table that missed the tolerance says so (and
    :func:`fsdecouple.core.decouple.usable` may refuse it).

    Each level costs only the kernel sums at its new knots (values and slopes)
    and at its midpoints, the largest-error points of a Hermite cubic, which
    decide whether to refine and are also the next level's new knots.  The full
    check grid (:data:`CHECKS_PER_INTERVAL` per interval) is evaluated only for a
    table that is about to be returned.  A common grid lets the evaluator
    compute one table index per input voltage for both chi.
    """
    slope_fns = [_slope_fn(c) for c in chis]
    n_sv = sum(c.support_vectors.size for c in chis)
    floors = [FLOOR_FACTOR * np.finfo(float).eps * abs(c.output_scale) * np.abs(c.dual_coef).sum()
              for c in chis]

    def full_check_cost(n: int) -> int:
        return (n * (2 * CHECKS_PER_INTERVAL + 1) + 1) * n_sv

    n = MIN_INTERVALS
    x = knots(lo, hi, n)
    values = [c(x) for c in chis]
    slopes = [s(x) for s in slope_fns]
    spent = 2 * x.size * n_sv
    history: list[tuple[int, list[float]]] = []  # (intervals, midpoint error per chi)
    while True:
        mid = knots(lo, hi, 2 * n, 1, 2)  # midpoints of n = the new knots of 2n
        mid_values = [c(mid) for c in chis]
        spent += mid.size * n_sv
        tables = [ChiSurrogate(lo, hi, v, s, 0.0) for v, s in zip(values, slopes, strict=True)]
        errs = [_max_error(c.name, t, mid, e) for c, t, e in zip(chis, tables, mid_values, strict=True)]
        if all(e <= tolerance for e in errs):
            full = [measured_error(c, t) for c, t in zip(chis, tables, strict=True)]
            spent += full_check_cost(n)
            if all(e <= tolerance for e in full):
                return [replace(t, max_error=e) for t, e in zip(tables, full, strict=True)]
        stalled = [
            e > prev / STALL_FACTOR and e <= floor
            for e, prev, floor in zip(errs, history[-1][1], floors, strict=True)
        ] if history else [False] * len(chis)
        history.append((n, errs))
        done = any(stalled) and all(s or e <= tolerance for s, e in zip(stalled, errs, strict=True))
        # the next level: slopes at n new knots, 2n midpoints, and its full check
        next_cost = n * n_sv + 2 * n * n_sv + full_check_cost(2 * n)
        if done or 2 * n > MAX_INTERVALS or spent + next_cost > budget:
            best, _ = min(history, key=lambda h: max(h[1]))
            step = n // best
            tables = [ChiSurrogate(lo, hi, v[::step], s[::step], 0.0)
                      for v, s in zip(values, slopes, strict=True)]
            return [replace(t, max_error=measured_error(c, t)) for c, t in zip(chis, tables, strict=True)]
        spent += n * n_sv
        values = [_interleave(v, e) for v, e in zip(values, mid_values, strict=True)]
        slopes = [_interleave(s, f(mid)) for s, f in zip(slopes, slope_fns, strict=True)]
        n *= 2


def table_interval(lo: float, hi: float) -> tuple[float, float]:
    """The calibrated range [lo, hi] widened by :data:`MARGIN` of its span each side."""
    span = max(hi - lo, 1e-3)
    return lo - MARGIN * span, hi + MARGIN * span
