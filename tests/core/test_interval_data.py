"""The interval data a model file carries (core/interval_data.py, issue 33): the
stored sweep model's checks, the span against the model's calibrated loads, and
the Jacobians' inverse its variances use.  Its fit and its variance against Monte
Carlo: tests/evaluation/test_sweep_model.py; the checks at load:
tests/evaluation/test_intervals.py."""

from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np
import pytest

from fsdecouple.axes import DEFAULT
from fsdecouple.core.interval_data import _inverse, check_sweep_model
from fsdecouple.errors import InputError
from fsdecouple.evaluation.sweep_model import fit_sweep_model
from fsdecouple.sim.simulate import SimulatedSensor, simulate_calibration


def _doc():
    return fit_sweep_model(simulate_calibration(SimulatedSensor(), 2, 2), DEFAULT)["model"]


@pytest.mark.parametrize("edit, match", [
    (lambda d: d["noise_variance"].__setitem__(1, -1.0), "noise_variance is"),
    (lambda d: d["noise_variance"].__setitem__(1, 0.0), "noise_variance is"),
    (lambda d: d["peak"].__setitem__(0, float("nan")), "peak is"),
    (lambda d: d["shape"][1].__setitem__(0, []), "shape {load y, output 1} is []"),
    (lambda d: d["shape"][1][0].__setitem__(0, float("inf")), "shape {load y, output 1} is"),
    (lambda d: d["covariance"][2][0].__setitem__(0, [-1.0] + d["covariance"][2][0][0][1:]),
     "covariance {load z, output 1} is"),
    (lambda d: d["span"].__setitem__(0, [1.0, -1.0]), "span is"),
    (lambda d: d.pop("span"), "span is None"),
    (lambda d: d["covariance"].pop(), "covariance is"),
    (lambda d: d.pop("shape"), "shape is None"),
    (lambda d: d["peak"].__setitem__(1, 50.0), "peak of y is 50.0, expected the largest |load|"),
    (lambda d: d["shape"][0].__setitem__(0, [1e300] * len(d["shape"][0][0])),
     "reading's standard deviation at the span's ends is nan"),
    (lambda d: d["noise_variance"].__setitem__(0, 1e300), "reading's standard deviation"),
])
def test_damaged_sweep_models_are_refused(edit, match):
    doc = _doc()
    check_sweep_model(doc, DEFAULT.labels)  # as fitted: accepted
    edit(doc)
    with pytest.raises(InputError, match=f"damaged \\(least_squares {re.escape(match)}"):
        check_sweep_model(doc, DEFAULT.labels)


@pytest.mark.parametrize("n", [3, 6])
def test_the_jacobians_inverse_is_lapack_s_and_singular_rows_are_named(n):
    """Three components: the adjugate; six: LAPACK's; either way numpy's inverse to
    rounding, and a zero or rank-deficient J flagged (its rows get the identity)."""
    rng = np.random.default_rng(n)
    jac = rng.normal(size=(200, n, n)) + 3 * np.eye(n)  # well conditioned
    jac[5] = 0.0
    jac[6, 1] = 2 * jac[6, 0]
    jac[7, 0, 0] = np.nan
    inv, ok = _inverse(jac)
    assert ok.tolist() == [i not in (5, 6, 7) for i in range(200)]
    assert inv[ok] == pytest.approx(np.linalg.inv(jac[ok]), abs=1e-12)
    assert np.array_equal(inv[~ok], np.broadcast_to(np.eye(n), (3, n, n)))


def _owner(loads):
    """What the checks read of the model a sweep model belongs to: its calibrated loads
    and omega's slopes k (the simulator's, which the fit's k estimates to ~1e-3)."""
    return SimpleNamespace(calibrated_loads=np.asarray(loads, dtype=float), k=SimulatedSensor().k)


def test_the_span_must_be_the_model_s_calibrated_loads():
    """A span scaled with its peak (both 1e-300) left every log row beyond it and the
    bounds NaN with status ok; within a tenth of the span the noise's difference passes.
    Without the model to compare with, the reading's standard deviation, 1e297 spans
    of that span, refuses it too."""
    doc = _doc()
    loads = np.array(doc["span"])
    check_sweep_model(doc, DEFAULT.labels, _owner(loads + 0.05 * (loads[:, 1:] - loads[:, :1])))
    doc["peak"], doc["span"] = [1e-300] * 3, [[-1e-300, 1e-300]] * 3
    with pytest.raises(InputError, match=re.escape("span of x is [-1e-300, 1e-300], expected the "
                                                   "calibrated loads")):
        check_sweep_model(doc, DEFAULT.labels, _owner(loads))
    with pytest.raises(InputError, match="reading's standard deviation at the span's ends"):
        check_sweep_model(doc, DEFAULT.labels)


def test_the_own_slope_must_be_omega_s_along_the_span():
    """A shape edited so that g_xx' has a root inside the span (J singular there: the
    centre moved, the bounds 50 times wider; the span's ends alone did not show it),
    or with its slope doubled and more, is refused; the fitted one, within 1 % of k, not."""
    doc = _doc()
    owner = _owner(doc["span"])
    check_sweep_model(doc, DEFAULT.labels, owner)
    beta = doc["shape"][0][0]
    L = doc["peak"][0]
    slope = beta[0] / L  # dg_xx/df_x at 0 [V/N]
    # g = c (s - s^3 / (3 r^2)): g' = 0 at s = r = 0.3, g'(0) = omega's slope
    doc["shape"][0][0] = [beta[0], 0.0, -beta[0] / (3 * 0.3 ** 2)]
    doc["covariance"][0][0] = np.diag(np.full(3, 1e-12)).tolist()
    assert abs(slope / owner.k[0] - 1) < 0.01
    with pytest.raises(InputError, match=re.escape("own-load slope of x is ")) as err:
        check_sweep_model(doc, DEFAULT.labels, owner)
    # the slope found is said (at its root: near 0 x k), so an edited k or shape shows which
    found = float(re.search(r"slope of x is (\S+) times", str(err.value)).group(1))
    assert found < 0.5 and "expected 0.5-2 times" in str(err.value)


def test_a_negated_slope_is_named_as_the_disagreement_it_is():
    """omega's k_y negated (digest recomputed) was refused as a damaged 'shape ... is
    \"...\"'; the refusal now names k_y and the slope the interval data have (-1 x k_y)."""
    doc = _doc()
    owner = _owner(doc["span"])
    owner.k = owner.k * np.array([1.0, -1.0, 1.0])
    with pytest.raises(InputError) as err:
        check_sweep_model(doc, DEFAULT.labels, owner)
    msg = str(err.value)
    found = float(re.search(r"own-load slope of y is (\S+) times omega's k_y", msg).group(1))
    assert found == pytest.approx(-1.0, abs=0.02) and "slopes disagree" in msg
