"""Building the chi surrogates: knot reuse, the stall rule, the budget, honest errors."""

from __future__ import annotations

from dataclasses import replace

import fsdecouple.model as model_module
import fsdecouple.surrogate as surrogate
import numpy as np

from fsdecouple.core.decouple import MAX_SURROGATE_ERROR, usable
from fsdecouple.core.kernel import rbf_sum_slope
from fsdecouple.core.model import Chi
from fsdecouple.core.surrogate import (
    CHECKS_PER_INTERVAL,
    MIN_INTERVALS,
    build_pair,
    check_points,
    table_interval,
)


class Counting:
    """A chi that counts the points its kernel sum is evaluated at."""

    def __init__(self, chi):
        self.chi, self.points = chi, 0

    def __getattr__(self, name):
        return getattr(self.chi, name)

    def __call__(self, u):
        self.points += np.size(u)
        return self.chi(u)


def narrow_pair():
    """Two chi of narrow Gaussians (width ~0.1 V over 2 V): many doublings to 1e-10 V."""
    rng = np.random.default_rng(3)
    sv = np.sort(rng.uniform(-1, 1, 40))
    return [Chi(name, 50.0, sv, rng.uniform(-5, 5, sv.size), 0.01) for name in ("xy", "zy")]


def true_error(chi, s):
    """max |table - kernel sum| on the table's own check grid, as the file records it."""
    x = check_points(s.lo, s.hi, s.intervals, CHECKS_PER_INTERVAL)
    x = x[s.covers(x)]
    return float(np.max(np.abs(s(x) - chi(x))))


def test_refined_table_equals_one_built_directly_at_its_size():
    """Knots reused across doublings are bit for bit the knots of the final grid."""
    pair = narrow_pair()
    tables = build_pair(pair, -1.2, 1.2)
    n = tables[0].intervals
    assert n >= 8 * MIN_INTERVALS  # at least three doublings reused knots
    x = -1.2 + (1.2 - -1.2) * np.arange(n + 1) / n
    for c, s in zip(pair, tables, strict=True):
        np.testing.assert_array_equal(s.values, c(x))
        np.testing.assert_array_equal(s.slopes, rbf_sum_slope(x, c.support_vectors, c.dual_coef,
                                                              c.gamma))
        assert s.max_error == true_error(c, s) <= surrogate.TOLERANCE


def test_unreachable_tolerance_stalls_early_and_records_the_true_error(model, monkeypatch):
    """At the kernel sum's rounding floor doubling stops helping, so refinement stops
    within a few doublings, not at MAX_INTERVALS.  Outputs in mV (output_scale 1e3)
    put the floor (~5e-9) above the gate: the table is recorded as measured and
    refused, so the model decouples by the exact kernel sum."""
    slope_points = []

    def counting_slope(x, *args):
        slope_points.append(np.size(x))
        return rbf_sum_slope(x, *args)

    monkeypatch.setattr(model_module, "rbf_sum_slope", counting_slope)  # Chi.slope's, the one
    # the kernel sum everywhere: this table interval does not put the range's ends on knots
    pair = [Counting(replace(c, output_scale=1e3, extrapolation="kernel"))
            for c in model.chi.values() if c.name[1] == "y"]
    lo, hi = table_interval(min(c.input_range[0] for c in pair), max(c.input_range[1] for c in pair))
    tables = build_pair(pair, lo, hi, tolerance=1e-30)
    # each knot's slope is computed once: at most three doublings (2^3 * MIN_INTERVALS knots)
    assert 0 < sum(slope_points) <= len(pair) * (8 * MIN_INTERVALS + 1)
    # values at the knots and midpoints of every level, plus one dense check
    dense = 8 * MIN_INTERVALS * (2 * CHECKS_PER_INTERVAL + 1) + 1
    assert all(c.points <= 2 * 16 * MIN_INTERVALS + dense for c in pair)
    for c, s in zip(pair, tables, strict=True):
        assert s.intervals <= 8 * MIN_INTERVALS
        assert s.max_error == true_error(c, s) > MAX_SURROGATE_ERROR
        assert not usable(s)


def test_budget_stops_with_the_best_table_so_far_and_an_honest_error():
    pair = narrow_pair()
    tables = build_pair(pair, -1.2, 1.2, budget=0)
    for c, s in zip(pair, tables, strict=True):
        assert s.intervals == MIN_INTERVALS
        assert s.max_error == true_error(c, s) > surrogate.TOLERANCE
        assert not usable(s)  # so fit warns and the model decouples exactly
