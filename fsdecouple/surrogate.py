"""Piecewise-cubic surrogates of the chi functions, verified against the kernel sum.

Each chi (eq. 4) is a smooth function of one prime voltage, but its exact value is
a sum of ~100 Gaussians whose dual coefficients reach C = 1000 and cancel to a
result of a few 10 mV.  A cubic Hermite interpolant on a uniform grid (values and
exact slopes of the kernel sum at the knots) reproduces it to ~1e-11 V with a few
hundred intervals and costs four table look-ups and a Horner step per input.

The grid is refined (interval count doubled) until the error measured on a dense
check grid is at most :data:`TOLERANCE`; that measured maximum is stored in the
model file beside the table, so a reader knows what the fast path promises.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .kernel import rbf_sum_slope

KIND = "hermite3-uniform"
# Target for the measured max |surrogate - kernel sum| per chi [V]: a tenth of
# the 1e-9 V promise, so that the two chi of one output stay far inside it.
TOLERANCE = 1e-10
CHECKS_PER_INTERVAL = 20  # dense check points per interval, plus knots and midpoints
MIN_INTERVALS, MAX_INTERVALS = 256, 1 << 17
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
        """Power-basis coefficients c0..c3 per interval, shape (4, intervals).

        On interval i, with s = (u - lo) * inv_step - i in [0, 1):
        chi(u) ~ ((c3 s + c2) s + c1) s + c0.
        """
        h = (self.hi - self.lo) / self.intervals
        y0, y1 = self.values[:-1], self.values[1:]
        d0, d1 = h * self.slopes[:-1], h * self.slopes[1:]
        return np.stack([y0, d0, 3.0 * (y1 - y0) - 2.0 * d0 - d1, 2.0 * (y0 - y1) + d0 + d1])

    def covers(self, u: np.ndarray) -> np.ndarray:
        """Where the table serves ``u``: 0 <= (u - lo) * inv_step < intervals.

        The evaluators use this very expression, so a voltage a hair below
        ``hi`` whose index rounds up to ``intervals`` is left to the exact path
        here too.
        """
        t = (np.asarray(u, dtype=float) - self.lo) * self.inv_step
        return (t >= 0) & (t < self.intervals)

    def __call__(self, u: np.ndarray) -> np.ndarray:
        """Surrogate chi [V] at prime voltages ``u`` [V] the table covers; NaN elsewhere."""
        u = np.asarray(u, dtype=float)
        c = self.coefficients()
        t = (u - self.lo) * self.inv_step
        inside = self.covers(u)
        i = np.where(inside, t, 0).astype(np.intp)
        s = t - i
        out = ((c[3, i] * s + c[2, i]) * s + c[1, i]) * s + c[0, i]
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


def check_points(lo: float, hi: float, intervals: int, per_interval: int) -> np.ndarray:
    """Knots, midpoints and ``per_interval`` evenly spread points inside each interval."""
    sub = np.arange(2 * per_interval + 1) / (2 * per_interval)  # includes 0 and 1/2
    knots = np.arange(intervals) / intervals
    x = lo + (hi - lo) * (knots[:, None] + sub[None, :] / intervals).ravel()
    return np.append(x, hi)


def _build(exact, slope, lo: float, hi: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    knots = lo + (hi - lo) * np.arange(n + 1) / n
    return exact(knots), slope(knots)


def build_pair(chis, lo: float, hi: float, tolerance: float = TOLERANCE) -> list[ChiSurrogate]:
    """Surrogates of the chi sharing one input axis, on one common grid of [lo, hi].

    The interval count doubles from :data:`MIN_INTERVALS` until every chi meets
    ``tolerance`` on the check grid.  A common grid lets the evaluator compute
    one table index per input voltage for both chi.
    """
    fns = []
    for c in chis:
        def exact(u, c=c):
            return c(u)

        def slope(u, c=c):
            x = np.asarray(u, dtype=float) / c.input_scale
            return rbf_sum_slope(x, c.support_vectors, c.dual_coef, c.gamma) * (
                c.output_scale / c.input_scale
            )

        fns.append((exact, slope))
    n = MIN_INTERVALS
    while True:
        out = []
        for exact, slope in fns:
            values, slopes = _build(exact, slope, lo, hi, n)
            s = ChiSurrogate(lo, hi, values, slopes, 0.0)
            x = check_points(lo, hi, n, CHECKS_PER_INTERVAL)
            x = x[s.covers(x)]  # hi, and any point whose index rounds to it, go the exact path
            err = float(np.max(np.abs(s(x) - exact(x))))
            if not np.isfinite(err):
                raise FloatingPointError(f"chi_{chis[len(out)].name}: surrogate error is {err}")
            out.append(ChiSurrogate(lo, hi, values, slopes, err))
        if all(s.max_error <= tolerance for s in out) or n >= MAX_INTERVALS:
            return out
        n *= 2


def table_interval(lo: float, hi: float) -> tuple[float, float]:
    """The calibrated range [lo, hi] widened by :data:`MARGIN` of its span each side."""
    span = max(hi - lo, 1e-3)
    return lo - MARGIN * span, hi + MARGIN * span
