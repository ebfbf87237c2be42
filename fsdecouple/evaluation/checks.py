"""The assumption checks of Section 2.1, computed from a fitted model.

1. Linearity of each non-coupling function omega: R^2 >= 0.99 (assumption 1).
2. Coupling errors below 5 % of the full-scale output of their channel.
3. Slopes of the corrected coupling functions, max |d chi / du| <= 0.05.
4. The resulting bound on the second-order coupling error, eq. (5)-(6), <= 0.25 %.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

COUPLING_LIMIT = 0.05  # fraction of full-scale output (Section 2.1)
SLOPE_LIMIT = 0.05  # |d chi/du| (Section 2.1)
SECOND_ORDER_LIMIT = COUPLING_LIMIT * SLOPE_LIMIT  # 0.25 %, eq. (6)
GRID_POINTS = 2001  # dense grid over each chi's calibrated input range


@dataclass(frozen=True)
class Check:
    """One assumption check: ``status`` is ``pass`` when ``value <= limit``
    (``>=`` for ``linearity``), else ``warn``."""

    name: str  # linearity | coupling | slope | second_order
    subject: str  # axis ("x") or chi ("xy")
    value: float
    limit: float
    status: str

    def to_dict(self) -> dict:
        return asdict(self)


def chi_slope(chi, u: np.ndarray) -> np.ndarray:
    """d chi/du at prime voltages u: eq. (10) differentiated analytically (``Chi.kernel_slope``,
    the one slope every table is built from)."""
    return chi.kernel_slope(np.asarray(u, dtype=float))


def _grid(chi) -> np.ndarray:
    lo, hi = chi.input_range
    return np.linspace(lo, hi, GRID_POINTS)


def assumption_checks(model) -> list[Check]:
    """All checks of Section 2.1 for a fitted :class:`~fsdecouple.core.model.CouplingErrorModel`.

    Full-scale outputs are u_a(FS) = |k_aa| F_a(FS).  The coupling error of channel
    a is e_a = e_ab + e_ac (eq. 1), bounded by max|chi_ab| + max|chi_ac| over the
    calibrated ranges.  Eq. (6) bounds the second-order error of chi_ab by
    max|chi_ab'| * |u_b(t) - u_bb(t)| / u_b(FS), i.e. the slope times the coupling
    fraction of its input channel b.
    """
    u_fs = np.abs(model.k) * np.asarray(model.settings.full_scale)
    checks = []
    labels = model.layout.labels
    for axis in labels:
        r2 = float(model.report.r2.get(axis, np.nan)) if model.report else np.nan
        limit = model.settings.min_r2
        checks.append(Check("linearity", axis, r2, limit, "pass" if r2 >= limit else "warn"))
    peak = {name: float(np.abs(c(_grid(c))).max()) for name, c in model.chi.items()}
    coupling = {}
    for a, axis in enumerate(labels):
        total = sum(v for name, v in peak.items() if model.chi[name].output_axis == a)
        coupling[axis] = float(total / u_fs[a])
        checks.append(Check("coupling", axis, coupling[axis], COUPLING_LIMIT,
                            "pass" if coupling[axis] <= COUPLING_LIMIT else "warn"))
    for name, c in model.chi.items():
        slope = float(np.abs(chi_slope(c, _grid(c))).max())
        checks.append(Check("slope", name, slope, SLOPE_LIMIT,
                            "pass" if slope <= SLOPE_LIMIT else "warn"))
        bound = float(slope * coupling[labels[c.input_axis]])
        checks.append(Check("second_order", name, bound, SECOND_ORDER_LIMIT,
                            "pass" if bound <= SECOND_ORDER_LIMIT else "warn"))
    return checks
