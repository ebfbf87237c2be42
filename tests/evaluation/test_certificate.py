"""The certificate's figures, recomputed from their definitions on small hand-made sets.

Every expected figure below is computed by a plain loop over the readings as ISO 376
and EURAMET cg-4 state them (normal equations for the cubic, explicit max/min/mean),
not by the module's array code.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from fsdecouple.config import load_config
from fsdecouple.data.calibration import from_table
from fsdecouple.errors import InputError
from fsdecouple.evaluation.budget import budget, reading_noise
from fsdecouple.evaluation.certificate import certificate, check_matches
from fsdecouple.evaluation.iso376 import classify, component_steps, interpolation_errors, resolution
from fsdecouple.evaluation.verdict import calibrate

LOADS = [0.0, 20.0, 40.0, 60.0, 80.0, 100.0, 60.0, 20.0, 0.0]  # up, then down, zero at both ends


def _sweep_rows(rep: int, axis: str, gain: float, offset: float, wobble) -> list[tuple]:
    rows = []
    for i, f in enumerate(LOADS):
        u = [offset, offset, offset]
        a = "xyz".index(axis)
        # a slightly nonlinear prime output, a reading that differs on the way down,
        # and a zero that drifts by 2e-4 between the start and the end of the sweep
        u[a] += gain * f + 1e-6 * f * f + wobble[i] + (2e-4 * rep if i == len(LOADS) - 1 else 0.0)
        u[(a + 1) % 3] += 0.01 * gain * f
        rows.append((rep, axis, *(f if b == axis else 0.0 for b in "xyz"), *u))
    return rows


@pytest.fixture(scope="module")
def hand_set():
    rng = np.random.default_rng(3)
    rows = []
    for rep in (1, 2, 3):
        for axis, gain in zip("xyz", (0.0133, -0.0128, 0.008), strict=True):
            rows += _sweep_rows(rep, axis, gain, rng.uniform(-0.05, 0.05),
                                np.round(rng.normal(0, 2e-4, len(LOADS)), 7))
    table = pd.DataFrame(rows, columns=["repetition", "axis", "fx", "fy", "fz", "ux", "uy", "uz"])
    return table, from_table(table, replace(load_config(), min_repetitions=1))


def _readings(table: pd.DataFrame, axis: str):
    """X[rep][load] on the way up and X'[rep][load] on the way down, zero-corrected by
    the mean of the sweep's zero rows, and (i_0, i_f, X_N) per repetition."""
    up, down, zero = {}, {}, {}
    col, fcol = f"u{axis}", f"f{axis}"
    for rep, g in table[table["axis"] == axis].groupby("repetition"):
        f, u = g[fcol].tolist(), g[col].tolist()
        z = sum(v for v, ff in zip(u, f, strict=True) if ff == 0.0) / f.count(0.0)
        x = [v - z for v in u]
        peak = max(range(len(f)), key=lambda i: abs(f[i]))
        up[rep], down[rep] = {}, {}
        for i, ff in enumerate(f):
            if ff == 0.0:
                continue
            if ff not in up[rep]:
                up[rep][ff] = x[i]
            elif i > peak:
                down[rep].setdefault(ff, x[i])
        # i_0 and i_f are read at zero load, and every load read on the way down was
        # also read on the way up (else its reversibility error would have no reference)
        assert f[0] == 0.0 == f[-1] and abs(f[peak]) == max(LOADS), (rep, f)
        assert set(down[rep]) <= set(up[rep]) and down[rep], (rep, down[rep])
        zero[rep] = (x[0], x[-1], x[peak])
    return up, down, zero


def test_b_b_prime_f_c_f_0_v_equal_their_definitions(hand_set):
    table, calib = hand_set
    for a, axis in enumerate("xyz"):
        st = component_steps(calib, a)
        up, down, zero = _readings(table, axis)
        loads = sorted({f for r in up.values() for f in r})
        assert st.loads.tolist() == loads
        means = []
        for j, f in enumerate(loads):
            xs = [up[r][f] for r in sorted(up)]
            mean = sum(xs) / len(xs)
            means.append(mean)
            assert st.figures["b"][j] == pytest.approx(100 * (max(xs) - min(xs)) / abs(mean), abs=1e-9)
            bp = 100 * abs(xs[1] - xs[0]) / abs((xs[0] + xs[1]) / 2)
            assert st.figures["b_prime"][j] == pytest.approx(bp, abs=1e-9)
            back = [down[r][f] - up[r][f] for r in sorted(up) if f in down[r]]
            if back:
                assert st.figures["v"][j] == pytest.approx(100 * sum(back) / len(back) / abs(mean),
                                                           abs=1e-9)
            else:
                assert np.isnan(st.figures["v"][j])
        # X_a: normal equations of the cubic without constant term, in plain sums
        m = [[sum(f ** (p + q) for f in loads) for q in (1, 2, 3)] for p in (1, 2, 3)]
        rhs = [sum(f ** p * x for f, x in zip(loads, means, strict=True)) for p in (1, 2, 3)]
        c = np.linalg.solve(np.array(m), np.array(rhs))
        for j, f in enumerate(loads):
            xa = c[0] * f + c[1] * f ** 2 + c[2] * f ** 3
            assert st.figures["f_c"][j] == pytest.approx(100 * (means[j] - xa) / xa, abs=1e-7)
        # f_0 at the largest step: the largest |100 (i_f - i_0) / X_N| over repetitions
        f0 = [100 * (i_f - i_0) / abs(xn) for i_0, i_f, xn in zero.values()]
        top = loads.index(100.0)
        assert st.figures["f_0"][top] == pytest.approx(max(f0, key=abs), abs=1e-9)
        assert np.isnan(np.delete(st.figures["f_0"], top)).all()


def test_interpolation_of_exact_cubic_is_zero_and_of_few_steps_is_not_exact():
    f = np.array([10.0, 20.0, 30.0, 40.0, 50.0])
    x = 0.01 * f - 2e-5 * f ** 2 + 1e-7 * f ** 3
    assert np.abs(interpolation_errors(f, x)).max() < 1e-9
    # three steps: a quadratic through the origin, which cannot pass a bent set exactly
    f3, x3 = np.array([1.0, 2.0, 3.0]), np.array([1.0, 2.1, 2.9])
    got = interpolation_errors(f3, x3)
    c = np.linalg.lstsq(np.column_stack([f3, f3 ** 2]), x3, rcond=None)[0]
    xa = c[0] * f3 + c[1] * f3 ** 2
    assert got == pytest.approx(100 * (x3 - xa) / xa)


def test_class_from_the_iso_376_limits_at_steps_from_ten_percent(hand_set):
    _, calib = hand_set
    st = component_steps(calib, 0)
    n = st.loads.size
    # ISO 376:2011 Table 2: b 0.05/0.10/0.20/0.40, b' 0.025/0.05/0.10/0.20, |f_c| 0.025/0.05/0.10/0.20
    for name, b, bp, fc, want in (("00", 0.05, 0.025, -0.025, "00"), ("0.5", 0.06, 0.01, 0.0, "0.5"),
                                  ("0.5 by b'", 0.0, 0.03, 0.0, "0.5"), ("1", 0.2, 0.05, -0.1, "1"),
                                  ("2 by f_c", 0.0, 0.0, 0.15, "2"), ("none", 0.41, 0.0, 0.0, "none"),
                                  ("none by f_c", 0.0, 0.0, -0.21, "none")):
        st.figures = {**st.figures, "b": np.full(n, b), "b_prime": np.full(n, bp),
                      "f_c": np.full(n, fc)}
        assert classify(st, 100.0) == {"+": want}, name
    # a bad step below 10 % of full scale does not count; at 10 % it does
    st.figures = {**st.figures, "b": np.where(st.loads < 21.0, 5.0, 0.02),
                  "b_prime": np.zeros(n), "f_c": np.zeros(n)}
    assert classify(st, 250.0) == {"+": "00"}  # 20 < 25 = 10 % of 250
    assert classify(st, 200.0) == {"+": "none"}  # 20 = 10 % of 200


def test_budget_adds_the_contributions_in_quadrature(hand_set):
    _, calib = hand_set
    st = component_steps(calib, 1)
    r = resolution(calib, 1)
    u_model = np.linspace(0.01, 0.05, st.loads.size)
    b = budget(st, u_model, 0.04, r)
    for j, f in enumerate(st.loads):
        xs = st.X[j]
        mean = xs.mean()
        s = math.sqrt(sum((x - mean) ** 2 for x in xs) / (len(xs) - 1))
        w = {"reference": 0.04 / 100 / 2,
             "reproducibility": s / math.sqrt(len(xs)) / abs(mean),
             "resolution": math.sqrt(2 * (r / (2 * math.sqrt(3))) ** 2) / abs(mean),
             "interpolation": abs(st.figures["f_c"][j]) / 100 / math.sqrt(3),
             "zero": np.nanmax(np.abs(st.figures["f_0"])) / 100 / math.sqrt(3),
             "model": u_model[j] / abs(f)}
        for k, v in w.items():
            assert b[k][j] == pytest.approx(v, rel=1e-9), k
        wc = math.sqrt(sum(v * v for v in w.values()))
        assert b["U"][j] == pytest.approx(2 * wc * abs(f), rel=1e-9)


def test_resolution_is_the_step_readings_are_recorded_in(hand_set):
    table, calib = hand_set
    # readings with every digit of a double: the smallest step between two of them
    raw = sorted(set(calib.points["uy_raw"]))
    assert resolution(calib, 1) == pytest.approx(min(np.diff(raw)[np.diff(raw) > 0]))
    # whole ADC counts, however sparse: 1 count; printed to 4 decimals: 1e-4
    counts = table.assign(ux=np.round(table["ux"] * 1e6), uy=np.round(table["uy"], 4))
    read = from_table(counts, replace(load_config(), min_repetitions=1))
    assert resolution(read, 0) == 1.0 and resolution(read, 1) == pytest.approx(1e-4)


def test_reading_noise_recovers_the_simulated_noise(calib, model):
    # the simulator's noise is 0.5 mV per reading, 1/k = 75, 78, 125 N/V
    s, m = reading_noise(calib, model.k)
    assert m == 1.0
    assert s == pytest.approx(0.0005 * np.abs(1 / model.k), rel=0.15)  # ~1000 dof: ~5 % scatter


@pytest.fixture(scope="module")
def certified(calib, settings):
    model = calibrate(calib, settings)
    return model, certificate(model, calib)


@pytest.mark.slow  # a fit with the held-out verdict: seconds of CPU; the not-slow run stays under a minute
def test_certificate_on_a_simulated_sensor_matches_the_definitions(certified, calib):
    model, doc = certified
    recs = pd.DataFrame(doc["records"])
    assert doc["format"] == "fsdecouple.certificate"
    for axis in "xyz":
        s = calib.sweep(axis)
        f = s[f"f{axis}"].to_numpy()
        for load in np.unique(f[f != 0]):
            xs = s.loc[f == load].groupby("repetition")[f"u{axis}"].first().to_numpy()
            got = recs[(recs["axis"] == axis) & (recs["load"] == load)].set_index("metric")["value"]
            assert got["b"] == pytest.approx(100 * (xs.max() - xs.min()) / abs(xs.mean()), abs=1e-6)
            assert got["b_prime"] == pytest.approx(
                100 * abs(xs[1] - xs[0]) / abs((xs[0] + xs[1]) / 2), abs=1e-6)
            assert got["U"] > 0
    assert {(c["axis"], c["sign"]) for c in doc["classes"]} == {
        ("x", "+"), ("x", "-"), ("y", "+"), ("y", "-"), ("z", "-")}
    budget_u = {(b["axis"], b["load"]): b["U"] for b in doc["budget"]}
    assert all(budget_u[(r["axis"], r["load"])] == r["value"]
               for r in doc["records"] if r["metric"] == "U")
    # the model file's U (written by fit, for compare) is the certificate's
    steps = model.report.certificate["steps"]["x"]
    assert steps["U"] == pytest.approx([budget_u[("x", f)] for f in steps["load"]])


@pytest.mark.slow  # over ~0.8 s: the not-slow run stays under a minute
def test_one_repetition_has_no_b_and_says_why(calib, settings):
    one = calib.subset([1])
    model = calibrate(one, replace(settings, min_repetitions=1))
    doc = certificate(model, one)
    metrics = {r["metric"] for r in doc["records"]}
    assert "b" not in metrics and "b_prime" not in metrics and "U" in metrics
    assert any("one repetition" in n for n in doc["notes"])
    # without b and b' ISO 376 gives no class, however small f_c is
    assert {c["class"] for c in doc["classes"]} == {"none"}


def test_a_set_the_model_was_not_fitted_on_is_refused(certified, calib):
    model, _ = certified
    other = replace(calib, files=(("rep1.csv", "0" * 64),))
    with pytest.raises(InputError, match="does not match the model file"):
        check_matches(model, other, "m.json")
    with pytest.raises(InputError, match="the config's full_scale is not the model's"):
        check_matches(model, calib, "m.json", replace(model.settings, full_scale=(1.0, 2.0, 3.0)))


def test_out_and_back_sets_zeroed_by_fit_keep_iso_deflections_from_the_zero_rows(hand_set):
    """The hand set goes up and down: fit zeroes it from all points (issue 24), the
    certificate's figures still take each deflection from its sweep's zero rows."""
    table, calib = hand_set
    assert calib.zero == "fit" and calib.zero_auto
    rows = from_table(table, replace(load_config(), zero="rows", min_repetitions=1))
    assert rows.zero == "rows" and not rows.zero_auto
    for a in range(3):
        auto, by_rows = component_steps(calib, a), component_steps(rows, a)
        np.testing.assert_allclose(auto.X, by_rows.X, rtol=1e-12)
        for name, values in auto.figures.items():
            np.testing.assert_allclose(values, by_rows.figures[name], rtol=1e-9, atol=1e-12,
                                       err_msg=name)
