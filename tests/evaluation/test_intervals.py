"""Conformal intervals: the quantile, the noise model's scales, and the checks."""

from __future__ import annotations

import math
import re
from dataclasses import replace

import numpy as np
import pytest
from conftest import SAMPLE, assert_one_line_error, invoke

from fsdecouple.errors import InputError
from fsdecouple.evaluation.intervals import (
    check_coverage,
    half_widths,
    interval_calibration,
    interval_names,
    with_intervals,
)


def _with_scores(model, scores, sigma=(1.0, 2.0, 3.0)):
    cal = {"scores": list(scores),
           "components": {a: {"sigma": s, "scores": None} for a, s in zip("xyz", sigma, strict=True)}}
    return replace(model, report=replace(model.report, certificate={"interval": cal}))


def test_half_width_is_the_conformal_quantile_times_sigma(model):
    m = _with_scores(model, np.arange(1.0, 20.0))  # n = 19 scores: 1, 2, ..., 19
    # split conformal: the ceil((n + 1) P)-th smallest score; P = 0.9 -> the 18th
    assert half_widths(m, 0.9) == pytest.approx([18.0, 36.0, 54.0])
    assert half_widths(m, 0.5) == pytest.approx([10.0, 20.0, 30.0])  # ceil(10) = 10th
    with pytest.raises(InputError, match="up to P = 0.950"):
        half_widths(m, 0.96)  # ceil(19.2) = 20 > 19: no score is large enough


def test_bounds_without_outputs_are_symmetric(model):
    m = _with_scores(model, np.arange(1.0, 20.0))
    f = np.array([[1.0, -2.0, 3.0], [0.0, 0.0, 0.0]])
    out = with_intervals(m, f, 0.5)
    assert out[:, :3].tolist() == f.tolist()
    assert out[:, 3::2] == pytest.approx(f - [10.0, 20.0, 30.0])
    assert out[:, 4::2] == pytest.approx(f + [10.0, 20.0, 30.0])
    assert interval_names(("fx", "fy")) == ("fx_lo", "fx_hi", "fy_lo", "fy_hi")


def _held_out(rng, n, s, m, tau, comps=3, step=10.0):
    """Single-axis held-out points: each loads one component (a zero-load point per 20),
    and every component's residual is the zero-corrected reading's noise s^2 (1 + 1/m)
    plus, from the one load, a model error of variance tau^2."""
    true = np.zeros((n, comps))
    axis = rng.integers(0, comps, n)
    true[np.arange(n), axis] = step * rng.integers(1, 11, n) * rng.choice([-1, 1], n)
    true[::20] = 0.0
    err = rng.normal(scale=s * math.sqrt(1 + 1 / m), size=(n, comps))
    err += rng.normal(scale=tau, size=(n, comps))
    err[::20] = 0.0  # a sweep's zero reading is its own reference
    return true, true + err


def test_the_model_share_is_the_held_out_excess_over_the_reading_noise():
    """With offsets fitted (zero: fit, m = inf) the model's share is measured."""
    rng = np.random.default_rng(0)
    s, m, n, nt, tau = 0.1, np.inf, 6, 4.0, 0.08  # tau^2 / s^2 = 0.64
    true, pred = _held_out(rng, 60_000, s, m, tau)
    cal = interval_calibration(true, pred, ("x", "y", "z"), np.full(3, s), zeros=m,
                               repetitions=n, trained=nt)
    # brute force: the excess of the loaded points' mean squared residual over the
    # reading's variance, less p = 1 / (2 n_t) = 0.125; scaled to n repetitions
    loaded = (true != 0).any(axis=1)
    excess = np.mean(((pred - true)[loaded] / s) ** 2) - 1.0
    assert excess == pytest.approx(0.64, abs=0.03)  # the simulation's own tau^2 / s^2
    p = 1.0 / (2 * nt)
    for c in cal["components"].values():
        assert c["sigma"] == s
        assert c["load_variance"] == pytest.approx((excess - p) * s * s * nt / n, rel=1e-9)
    # zero-load points score nothing; the rest are |r| / (s sqrt(1 + 1/m + v))
    assert len(cal["scores"]) == 3 * loaded.sum()
    v = excess - p
    expected = np.sort((np.abs(pred - true)[loaded] / (s * math.sqrt(1 + v))).ravel())
    assert cal["scores"] == pytest.approx(expected.tolist())
    assert cal["first_step"] == {"x": 10.0, "y": 10.0, "z": 10.0}


def test_with_zero_rows_the_model_share_is_the_zero_readings_whatever_the_rounds_show():
    """Zero rows: each chi inherits the mean of n_t sweeps' zero readings, s^2 / (m n_t);
    the rounds' excess (here tau^2 / s^2 = 0.64 or none) does not move it (issue 33)."""
    s, m, n, nt = 0.1, 2.0, 6, 4.0
    for seed, tau in ((3, 0.08), (4, 0.0)):
        true, pred = _held_out(np.random.default_rng(seed), 20_000, s, m, tau)
        cal = interval_calibration(true, pred, ("x", "y", "z"), np.full(3, s), zeros=m,
                                   repetitions=n, trained=nt)
        v = 1.0 / (m * nt)  # 0.125
        for c in cal["components"].values():
            assert c["load_variance"] == pytest.approx(v * s * s * nt / n, rel=1e-12)
        loaded = (true != 0).any(axis=1)
        expected = np.sort((np.abs(pred - true)[loaded] / (s * math.sqrt(1 + 1 / m + v))).ravel())
        assert cal["scores"] == pytest.approx(expected.tolist())


def test_without_excess_the_model_share_keeps_its_floor_and_zero_fit_drops_the_zero_reading():
    rng = np.random.default_rng(1)
    s, n, nt = 0.1, 6, 4.0
    true, pred = _held_out(rng, 30_000, s, m=np.inf, tau=0.0)  # zero: fit, no model error
    cal = interval_calibration(true, pred, ("x", "y", "z"), np.full(3, s), zeros=np.inf,
                               repetitions=n, trained=nt)
    # p = (1 + 0) / (2 n_t): the floor, since the excess (~0) less p is below it
    assert cal["components"]["y"]["load_variance"] == pytest.approx(s * s / (2 * nt) * nt / n)


def test_a_combined_load_row_carries_one_model_share_per_loaded_component(model):
    from fsdecouple.evaluation.intervals import row_sigma

    cal = {"scores": [1.0], "first_step": {"x": 10.0, "y": 10.0, "z": 5.0},
           "components": {a: {"sigma": 0.1, "scores": None, "load_variance": 0.02} for a in "xyz"}}
    f = np.array([[0.0, 0.0, 0.0], [50.0, 0.0, 0.0], [50.0, -80.0, -100.0], [5.0, 0.0, -2.5]])
    loaded = np.array([0.0, 1.0, 3.0, 0.5 + 0.5])  # min(1, |f_b| / L_b) summed by hand
    assert row_sigma(cal, f, "xyz") == pytest.approx(
        np.sqrt(0.01 + 0.02 * loaded)[:, None].repeat(3, axis=1))
    # a model file from before the share: sigma' alone
    old = {"scores": [1.0], "components": {a: {"sigma": 0.3, "scores": None} for a in "xyz"}}
    assert row_sigma(old, f, "xyz") == pytest.approx(np.full((4, 3), 0.3))


def test_intervals_hold_on_combined_loads_whose_errors_add():
    """The additive assumption, simulated: each loaded component adds an independent
    model error tau to every component.  Held-out single-axis points show one tau; rows
    loading all three show three.  Scores pooled as before the load term (the point's
    noise alone) cover too few rows; with it, P of them."""
    from fsdecouple.evaluation.intervals import _quantile, row_sigma

    rng = np.random.default_rng(2)
    s, m, n, nt, tau, p = 0.1, np.inf, 6, 4.0, 0.12, 0.95  # zero: fit: the share measured
    true, pred = _held_out(rng, 20_000, s, m, tau)
    cal = interval_calibration(true, pred, ("x", "y", "z"), np.full(3, s), zeros=m,
                               repetitions=n, trained=nt)
    # the final model's share is n_t / n of a round's: tau^2 n_t / n per loaded component
    rows = 50_000
    f = rng.uniform(20, 100, (rows, 3)) * rng.choice([-1, 1], (rows, 3))
    err = rng.normal(scale=s, size=(rows, 3))
    err += rng.normal(scale=tau * math.sqrt(nt / n), size=(rows, 3, 3)).sum(axis=2)
    h = _quantile(cal["scores"], p, "x") * row_sigma(cal, f, "xyz")
    covered = (np.abs(err) <= h).mean(axis=0)
    # v is tau^2 / s^2 = 1.44 less p = 0.125: q = 1.96 sqrt(2.44 / 2.315) = 2.012 and
    # sigma' = sqrt(1 + 3 v n_t/n) / sqrt(1 + 3 tau^2/s^2 n_t/n) = 0.967 of the rows'
    # sigma, so |N(0, 1)| <= 1.946 holds 0.948 of the rows
    v = 1.44 - 1 / (2 * nt)
    z = 1.96 * math.sqrt(2.44 / (1 + v)) * math.sqrt((1 + 3 * v * nt / n) / (1 + 3 * 1.44 * nt / n))
    assert covered == pytest.approx(np.full(3, math.erf(z / math.sqrt(2))), abs=0.006)  # sd 0.001
    without = _quantile(cal["scores"], p, "x") * s  # the reading's noise alone
    assert (np.abs(err) <= without).mean() < 0.75


def _sweeps(rng, n_sweeps, per, s, shared, comps=3, step=10.0):
    """Held-out single-axis sweeps of ``per`` loaded points: every point's residual is the
    reading's noise s plus its sweep's shared error N(0, shared^2) (a round's zero
    readings), the same on every component of the sweep."""
    axis = np.repeat(np.arange(n_sweeps) % comps, per)
    true = np.zeros((n_sweeps * per, comps))
    true[np.arange(true.shape[0]), axis] = step * np.tile(np.arange(1, per + 1), n_sweeps)
    err = rng.normal(scale=s, size=true.shape)
    err += np.repeat(rng.normal(scale=shared, size=(n_sweeps, comps)), per, axis=0)
    return true, true + err, np.repeat(np.arange(n_sweeps), per)


def test_zero_row_intervals_take_the_known_share_not_the_rounds_realisation():
    """Issue 33: the rounds' sweeps share errors (their zero readings' mean) that are not
    the final model's.  The final model's share is one bias per sensor, the same on
    every row, of variance rho^2 s^2 (rho^2 = sum_b c_b ramp_b, c_b known).  Held-out
    sweeps whose shared error is large (2 s) gave the pooled scores' intervals a
    coverage near 1 on every sensor; the within-sweep deviations, shifted by the known
    share's bias, cover at least P of a sensor's rows on CONFIDENCE of the sensors."""
    from scipy.stats import norm

    from fsdecouple.evaluation.intervals import half_widths

    rng = np.random.default_rng(5)
    s, shared, c, p = 0.1, 0.2, 1 / 6, 0.95
    true, pred, sweeps = _sweeps(rng, 60, 20, s, shared)
    f = np.full((1, 3), 50.0)  # every ramp 1: rho^2 = 3 c
    sensors = 20_000
    bias = rng.normal(scale=s * math.sqrt(3 * c), size=(sensors, 3))
    h = {}
    for label, extra in (("pooled", {}), ("within", {"sweeps": sweeps, "zero_variance": np.full(3, c)})):
        cal = interval_calibration(true, pred, ("x", "y", "z"), np.full(3, s), zeros=1.0,
                                   repetitions=6, trained=4.0, **extra)
        m = type("M", (), {})()  # half_widths reads the model's report and layout only
        m.report = type("R", (), {"certificate": {"interval": cal}})()
        m.layout = type("L", (), {"labels": ("x", "y", "z"), "overdetermined": False})()
        h[label] = half_widths(m, p, f)[0]
    # a sensor's coverage of its rows, noise N(bias, s^2): Phi's, not the module's
    covered = {k: norm.cdf((w - bias) / s) - norm.cdf((-w - bias) / s) for k, w in h.items()}
    assert (np.median(covered["pooled"], axis=0) > 0.985).all(), h  # the rounds' shared errors
    # at least P on 90 % of the sensors: 20 000 sensors (0.002) and the 1 200 deviations'
    # quantile (a 1 % change of h moves the share by about 0.01)
    share = (covered["within"] >= p).mean(axis=0)
    assert share == pytest.approx(np.full(3, 0.9), abs=0.025), share


def test_the_convolved_half_width_covers_p_at_the_sensors_bias_bound():
    """For deviations z ~ N(0, 1) and a bias b fixed per sensor, a row covers with
    probability Phi(Q - b) - Phi(-Q - b); the half-width is the Q at which that is P for
    b = Phi^-1(0.95) rho (90 % of sensors' biases lie within it), solved here by
    root-finding; at rho = 0 the conformal quantile."""
    from scipy.optimize import brentq
    from scipy.stats import norm

    from fsdecouple.evaluation.intervals import _convolved

    z = np.sort(np.random.default_rng(6).normal(size=5_000)).tolist()
    cal = {"deviations": z, "zero_variance": {"x": 0.5, "y": 0.0},
           "first_step": {"x": 10.0, "y": 10.0},
           "components": {"x": {"sigma": 2.0, "scores": None}, "y": {"sigma": 1.0, "scores": None}}}
    f = np.array([[0.0, 0.0], [5.0, 0.0], [50.0, 0.0], [50.0, 50.0]])  # rho^2 = 0, 0.25, 0.5, 0.5
    h = _convolved(cal, 0.95, f, ("x", "y"))
    bound = norm.ppf(0.95) * np.sqrt([0.0, 0.25, 0.5, 0.5])
    expected = np.array([brentq(lambda q, b=b: norm.cdf(q - b) - norm.cdf(-q - b) - 0.95, 0, 10)
                         for b in bound])
    assert h[:, 0] == pytest.approx(2.0 * expected, rel=0.01)  # 5 000 deviations: ~0.2 %
    assert h[:, 1] == pytest.approx(expected, rel=0.01)
    k = math.ceil((len(z) + 1) * 0.95)
    assert h[0, 1] == pytest.approx(np.sort(np.abs(z))[k - 1], rel=1e-12)


def test_the_zero_readings_share_is_the_variance_of_their_mean():
    """Brute force: G sweeps of m_g zero rows each, readings N(0, 1); the mean over the
    sweeps of each sweep's zero-row mean has the variance mean_g(1/m_g)/G."""
    import pandas as pd

    from fsdecouple.axes import DEFAULT
    from fsdecouple.data.zero import mean_offset_variance

    zeros_per_sweep = {"x": [1, 1, 1, 1, 1, 1], "y": [1, 2, 3, 1], "z": [2, 2]}
    rows = []
    for a, axis in enumerate(DEFAULT.labels):
        for rep, m in enumerate(zeros_per_sweep[axis], start=1):
            for load in [0.0] * m + [10.0, 20.0]:
                f = [0.0, 0.0, 0.0]
                f[a] = load
                rows.append((rep, axis, *f))
    points = pd.DataFrame(rows, columns=["repetition", "axis", *DEFAULT.loads])
    got = mean_offset_variance(points, DEFAULT)
    rng = np.random.default_rng(7)
    for b, axis in enumerate(DEFAULT.labels):
        ms = zeros_per_sweep[axis]
        draws = np.mean([rng.normal(size=(100_000, m)).mean(axis=1) for m in ms], axis=0)
        assert got[b] == pytest.approx(draws.var(), rel=0.02)  # 100 000 draws: 0.45 %


@pytest.mark.parametrize("field, value, match", [
    ("load_variance", -1.0, "load_variance of y is -1.0"),
    ("load_variance", float("nan"), "load_variance of y is nan"),
    ("first_step", {"y": 0.0}, "first_step of y is 0.0"),
    ("first_step", {"q": 1.0}, "first_step of q"),
    ("first_step", [1.0], "first_step is"),
    ("deviations", [1.0, float("inf")], "deviations are not finite numbers in ascending order"),
    ("deviations", [2.0, 1.0], "deviations are not finite numbers in ascending order"),
    ("zero_variance", {"y": -0.1}, "zero_variance of y is -0.1"),
    ("zero_variance", None, "zero_variance is None"),
    ("zero_shift", {"y": [0.0, float("nan"), 0.0]}, "zero_shift of y is [0.0, nan, 0.0]"),
    ("zero_shift", {"y": [0.0]}, "zero_shift of y is [0.0]"),
])
def test_damaged_interval_data_are_refused(model, field, value, match):
    m = _with_scores(model, np.arange(1.0, 20.0))
    cal = m.report.certificate["interval"]
    if field == "load_variance":
        cal["components"]["y"]["load_variance"] = value
    elif field in ("deviations", "zero_variance"):  # the within-sweep fields go together
        cal.update({"deviations": [0.5, 1.0], "zero_variance": {"x": 0.1}, field: value})
    else:
        cal[field] = value
    with pytest.raises(InputError, match=f"damaged \\({re.escape(match)}"):
        half_widths(m, 0.5)


@pytest.mark.parametrize("bad", [1.5, 0.0, 1.0, -0.1, True, "0.9"])
def test_coverage_must_lie_between_0_and_1(bad):
    with pytest.raises(InputError, match="between 0 and 1"):
        check_coverage(bad)


def test_a_model_without_residuals_refuses_intervals(model):
    with pytest.raises(InputError, match="no held-out residuals"):
        half_widths(replace(model, report=replace(model.report, certificate=None)), 0.9)


def test_a_model_file_with_a_broken_certificate_block_is_refused(model):
    from fsdecouple.core.modelfile import content_digest, model_from_dict, model_to_dict
    from fsdecouple.errors import ModelFileError

    doc = model_to_dict(replace(model, report=replace(model.report, certificate={"steps": {}})))
    doc["integrity"]["digest"] = content_digest(doc)  # digest-valid, so only the shape is wrong
    with pytest.raises(ModelFileError, match="certificate needs steps"):
        model_from_dict(doc, "m.json")


def _edited(path, tmp_path, edit):
    """The model file at ``path`` with ``edit(doc)`` applied and its digest recomputed."""
    import json

    from fsdecouple.core.modelfile import content_digest

    doc = json.loads(path.read_text())
    edit(doc["report"]["certificate"])
    doc["integrity"]["digest"] = content_digest(doc)
    out = tmp_path / "edited.json"
    out.write_text(json.dumps(doc))
    return out


def _least_squares(cert):
    return cert["interval"]["least_squares"]


def _earlier_construction(cert):
    """The interval data as a zero-rows fit without a sweep model writes them."""
    cal = cert["interval"]
    cal.pop("least_squares")
    cal["zero_variance"] = {axis: 0.01 for axis in cal["components"]}
    return cal


def _scaled(matrix, factor):
    return [[x * factor for x in row] for row in matrix]


def _scores(cert, a="x"):
    c = cert["interval"]["components"][a]
    return c["scores"] if c["scores"] is not None else cert["interval"]["scores"]


@pytest.mark.parametrize("edit, needle", [
    (lambda c: _scores(c).__setitem__(0, -5.0), "held-out score -5.0"),  # lo > hi on every row
    (lambda c: _scores(c).reverse(), "ascending"),  # the quantile read the wrong score
    (lambda c: c["interval"]["components"]["x"].__setitem__("sigma", 0.0), "sigma = 0.0"),
    (lambda c: c["interval"]["components"]["x"].__setitem__("sigma", 1e300), "sigma = 1e+300"),
    (lambda c: _scores(c).__setitem__(-1, 1e308), "times sigma"),
    (lambda c: c["steps"]["y"]["U"].__setitem__(0, 0.0), "y: U = 0.0"),  # E_n of x/0
    (lambda c: c["steps"]["z"]["model_error"].__setitem__(1, 1e300), "model_error = 1e+300"),
    (lambda c: c["steps"]["z"]["model_error"].__setitem__(1, -1.0), "model_error = -1.0"),
    # the sweep model (issue 33): checked at load too, not when a log is half read
    (lambda c: _least_squares(c).update(peak=[1e-300] * 3, span=[[-1e-300, 1e-300]] * 3),
     "span of x is [-1e-300, 1e-300], expected the calibrated loads"),  # bounds NaN, status ok
    (lambda c: _least_squares(c)["peak"].__setitem__(1, 50.0), "peak of y is 50.0"),
    (lambda c: _least_squares(c)["covariance"][0].__setitem__(0, _scaled(
        _least_squares(c)["covariance"][0][0], 1e300)), "model's standard deviation"),  # 1e147 wide
    (lambda c: _least_squares(c)["noise_variance"].__setitem__(2, 1e300), "reading's standard"),
    (lambda c: c["interval"]["deviations"].reverse(), "deviations are not finite numbers in ascending"),
    # zero-width intervals, status ok (a helper's check): every score 0, every deviation 0
    (lambda c: _scores(c).__setitem__(slice(None), [0.0] * len(_scores(c))), "held-out scores all 0.0"),
    (lambda c: c["interval"].__setitem__("deviations", [0.0] * len(c["interval"]["deviations"])),
     "deviations' mean square is 0.0"),
    (lambda c: c["interval"].__setitem__("deviations", [x / 10 for x in c["interval"]["deviations"]]),
     "deviations' mean square is 0.00"),
    (lambda c: _earlier_construction(c)["deviations"].__setitem__(
        slice(None), [0.0] * len(c["interval"]["deviations"])), "expected at least 0.01"),
    # scaled down or up (a reviewer's checks): bounds 0 wide, or 1e199 N with status ok
    (lambda c: _earlier_construction(c)["deviations"].__setitem__(
        slice(None), [x * 1e-3 for x in c["interval"]["deviations"]]), "expected at least 0.01"),
    (lambda c: _earlier_construction(c)["deviations"].__setitem__(
        slice(None), [x * 1e200 for x in c["interval"]["deviations"]]), "more than 1000 full scales"),
    (lambda c: c["interval"].__setitem__("scores", [x * 1e-3 for x in c["interval"]["scores"]]),
     "held-out scores' mean square"),
    (lambda c: _least_squares(c).__setitem__(
        "noise_variance", [x * 1e-20 for x in _least_squares(c)["noise_variance"]]),
     "expected a reading noise of at least 0.1 of x's held-out sigma"),
])
def test_edited_interval_and_step_data_are_refused_at_load_even_with_a_digest(
        sample_model, tmp_path, edit, needle):
    """The digest says the file is as written, not that its numbers can be (issue 34)."""
    from fsdecouple.core.modelfile import load_model
    from fsdecouple.errors import ModelFileError

    load_model(_edited(sample_model, tmp_path, lambda c: None))  # the untouched file loads
    with pytest.raises(ModelFileError, match=re.escape(needle)):
        load_model(_edited(sample_model, tmp_path, edit))


@pytest.mark.parametrize("args, edit", [
    (["compare", "{m}", "{e}", "--json"], lambda c: c["steps"]["x"]["U"].__setitem__(2, 0.0)),
    (["certificate", "{e}", str(SAMPLE / "calibration"), "--json"],
     lambda c: c["steps"]["x"]["model_error"].__setitem__(0, 1e300)),
    (["apply", "{e}", str(SAMPLE / "task_voltages.csv"), "--tare", "200", "--interval", "0.95",
      "-o", "{o}"], lambda c: _least_squares(c).update(peak=[1e-300] * 3, span=[[-1e-300, 1e-300]] * 3)),
])
def test_compare_and_certificate_json_refuse_an_edited_model_in_one_line(
        sample_model, tmp_path, args, edit):
    """Issue 34: E_n of x/0 and a model error of 1e300 were JSON ValueError tracebacks.
    Issue 33: a sweep model's span edited with its peak gave NaN bounds, exit 0."""

    e, out = _edited(sample_model, tmp_path, edit), tmp_path / "out.csv"
    r = invoke([a.format(m=sample_model, e=e, o=out) for a in args], 2)
    assert_one_line_error(r, str(e), "refit")
    assert not out.exists()


def test_the_zero_rows_shift_is_the_mean_error_of_their_readings():
    """Sweeps whose outputs are an offset per sweep plus one polynomial of the load
    (degree <= 5: the fitted offsets' own form), and whose zero rows read e off that
    offset.  The shift is the mean of (least-squares offset - zero row), re-derived here
    by its own least squares (the zero row is one of the fitted points, so it pulls the
    fitted offset by its leverage): about -0.83 mean(e) on this grid (issue 33)."""
    import pandas as pd

    from fsdecouple.axes import DEFAULT
    from fsdecouple.data.zero import zero_correct, zero_row_shift

    rng = np.random.default_rng(8)
    grid = np.arange(-100.0, 100.1, 10.0)
    rows, errors = [], {}
    for b, axis in enumerate(DEFAULT.labels):
        for rep in range(1, 5):
            offset, e = rng.uniform(-1, 1, 3), rng.normal(scale=0.01, size=3)
            errors[(axis, rep)] = e
            for load in grid:
                f = np.zeros(3)
                f[b] = load
                s = load / 100.0
                u = offset + np.array([0.3, -0.2, 0.1]) * s + 0.05 * s ** 2 - 0.02 * s ** 5
                if load == 0.0:
                    u = u + e
                rows.append((rep, axis, *f, *u))
    table = pd.DataFrame(rows, columns=["repetition", "axis", *DEFAULT.loads, *DEFAULT.outputs])
    points, offsets = zero_correct(table, DEFAULT, "rows")
    shift, ratio = zero_row_shift(points, offsets, DEFAULT)
    s = np.tile(grid / 100.0, 4)
    design = np.column_stack([np.repeat(np.eye(4), grid.size, axis=0), *(s ** k for k in range(1, 6))])
    for b, axis in enumerate(DEFAULT.labels):
        raw = table.loc[table["axis"] == axis, list(DEFAULT.outputs)].to_numpy()
        fitted = np.linalg.lstsq(design, raw, rcond=None)[0][:4]
        zero_rows = raw[np.tile(grid == 0.0, 4)]
        expected = np.mean(fitted - zero_rows, axis=0)
        assert shift[b] == pytest.approx(expected, abs=1e-12)
        e = np.mean([errors[(axis, rep)] for rep in range(1, 5)], axis=0)
        assert np.sign(shift[b]).tolist() == np.sign(-e).tolist()  # it takes the error back
        assert ratio[b] == pytest.approx(grid.sum() / (grid @ grid), abs=1e-15)  # 0: symmetric


def test_what_the_shift_leaves_has_the_variance_of_the_fitted_offsets_mean():
    """Brute force: sweeps read an offset per sweep, one polynomial of the load and
    N(0, 1) noise on every reading, zero rows too.  The model inherits - mean_g eps_g
    (eps_g: sweep g's zero-row mean error); the shift takes back its estimate, so
    shift + mean_g eps_g is what the centre keeps.  Its variance is shift_variance,
    re-derived here from the shift's own computation (zero_correct, zero_row_shift) fed
    one unit error at a time: a two-sided grid (the polynomial's offsets rest on both
    sides of the zero row), a one-sided one with the zero row at its end (extrapolated:
    more left), and a component of two levels, whose offsets are not fitted (all of
    mean_offset_variance left)."""
    import pandas as pd

    from fsdecouple.axes import DEFAULT
    from fsdecouple.data.zero import mean_offset_variance, shift_variance, zero_correct, zero_row_shift

    grids = {"x": np.arange(-100.0, 100.1, 10.0), "y": np.array([0.0, 0.0, 100.0]),
             "z": np.arange(0.0, -150.1, -5.0)}
    reps = 4
    layout_rows = [(rep, axis, b, load) for b, axis in enumerate(DEFAULT.labels)
                   for rep in range(1, reps + 1) for load in grids[axis]]
    rep, axis, comp, load = (np.array(c) for c in zip(*layout_rows, strict=True))
    f = np.zeros((len(load), 3))
    f[np.arange(len(load)), comp] = load
    s = load / np.abs(load).max()
    base = np.array([0.3, -0.2, 0.1]) * s[:, None] + 0.05 * s[:, None] ** 2
    zero = load == 0.0
    offset = np.random.default_rng(9).uniform(-1, 1, (reps, 3, 3))[rep - 1, comp]

    def left(noise):
        """shift + mean_g eps_g, (component b, output a), for the readings' errors ``noise``."""
        table = pd.DataFrame({"repetition": rep, "axis": axis, **dict(zip(DEFAULT.loads, f.T, strict=True)),
                              **dict(zip(DEFAULT.outputs, (offset + base + noise).T, strict=True))})
        points, offsets = zero_correct(table, DEFAULT, "rows")
        shift, _ = zero_row_shift(points, offsets, DEFAULT)
        eps = [np.mean([noise[(axis == a) & (rep == r) & zero].mean(axis=0)
                        for r in range(1, reps + 1)], axis=0) for a in DEFAULT.labels]
        return shift + np.array(eps)

    n = len(load)
    still = left(np.zeros((n, 3)))
    assert np.abs(still).max() < 1e-9  # the offsets and the shape are taken back exactly
    # Both parts are least squares and means of each output's own column, linear in its
    # errors: what is left of output a is L_b e_a, so for independent N(0, 1) readings its
    # variance is |L_b|^2, summed from the responses to one unit error at a time (three
    # readings a call, one in each output's column).  Exact: a simulation of 600 draws
    # had a standard error of 5.8 % and cost three times the CPU.
    var = np.zeros(3)
    for i in range(0, n, 3):
        noise = np.zeros((n, 3))
        rows = np.arange(i, min(i + 3, n))
        noise[rows, np.arange(rows.size)] = 1.0
        var += ((left(noise) - still) ** 2).sum(axis=1)
    points, _ = zero_correct(pd.DataFrame({"repetition": rep, "axis": axis,
                                           **dict(zip(DEFAULT.loads, f.T, strict=True)),
                                           **dict(zip(DEFAULT.outputs, (offset + base).T, strict=True))}),
                             DEFAULT, "rows")
    got = shift_variance(points, DEFAULT)
    assert got == pytest.approx(var, rel=1e-9)
    assert got[1] == pytest.approx(mean_offset_variance(points, DEFAULT)[1], rel=1e-12)
    assert got[0] < 0.25 * got[2]  # the one-sided grid extrapolates to its zero row
