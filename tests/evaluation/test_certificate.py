"""The certificate's figures, recomputed from their definitions on small hand-made sets.

Every expected figure below is computed by a plain loop over the readings as ISO 376
and EURAMET cg-4 state them (normal equations for the cubic, explicit max/min/mean),
not by the module's array code.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fsdecouple.config import load_config
from fsdecouple.core.modelfile import load_model
from fsdecouple.data.calibration import from_table
from fsdecouple.errors import InputError
from fsdecouple.evaluation.budget import budget, reading_noise
from fsdecouple.evaluation.calibrate import fit as calibrate
from fsdecouple.evaluation.certificate_doc import certificate, check_matches
from fsdecouple.evaluation.iso376 import (
    classify,
    classing,
    component_steps,
    interpolation_errors,
    resolution,
)

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
    """X[rep][load] on the way up and X'[rep][load] on the way down, deflections from the
    zero read before the series (ISO 376; these sweeps go 0, up, down, 0: the first row),
    and (i_0, i_f, X_N) per repetition."""
    up, down, zero = {}, {}, {}
    col, fcol = f"u{axis}", f"f{axis}"
    for rep, g in table[table["axis"] == axis].groupby("repetition"):
        f, u = g[fcol].tolist(), g[col].tolist()
        z = u[0]  # the mean of the zero rows instead put half the zero's drift into each X
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
            # ISO 376's reversibility is absolute: |X' - X| / X; the worst returning repetition
            back = [abs(down[r][f] - up[r][f]) / abs(up[r][f]) for r in sorted(up) if f in down[r]]
            if back:
                assert st.figures["v"][j] == pytest.approx(100 * max(back), abs=1e-9)
                assert st.figures["v"][j] >= 0
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


# ISO 376:2011 Table 2, written out here apart from the module's table [%]:
# class: b, b', |f_c|, |f_0|, v, c
TABLE_2 = {"00": (0.05, 0.025, 0.025, 0.012, 0.07, 0.025), "0.5": (0.10, 0.05, 0.05, 0.025, 0.15, 0.05),
           "1": (0.20, 0.10, 0.10, 0.050, 0.30, 0.10), "2": (0.40, 0.20, 0.20, 0.10, 0.50, 0.20)}
TABLE_3 = {"00": 0.01, "0.5": 0.02, "1": 0.05, "2": 0.10}  # reference forces, % at k = 2
ORDER = ("00", "0.5", "1", "2")


def _expected_class(fig: dict, ref: float | None = None) -> tuple[str, list[str]]:
    """The class and its limiting criteria by a plain loop over the tables above."""
    names = ("b", "b_prime", "f_c", "f_0", "v", "c")
    fails = {}
    for cls in ORDER:
        bad = [m for m, lim in zip(names, TABLE_2[cls], strict=True)
               if m in fig and abs(fig[m]) > lim]
        if ref is not None and ref > TABLE_3[cls]:
            bad = ["reference", *bad]
        fails[cls] = bad
    for i, cls in enumerate(ORDER):
        if not fails[cls]:
            return cls, (fails[ORDER[i - 1]] if i else [])
    return "none", fails["2"]


def _set_figures(st, **fig):
    n = st.loads.size
    st.figures = {m: np.full(n, fig[m]) if m in fig else np.full(n, np.nan)
                  for m in ("b", "b_prime", "f_c", "f_0", "v", "c")}


def test_class_from_every_criterion_of_iso_376_table_2(hand_set):
    _, calib = hand_set
    st = component_steps(calib, 0)
    cases = [dict(b=0.05, b_prime=0.025, f_c=-0.025), dict(b=0.06, b_prime=0.01, f_c=0.0),
             dict(b=0.0, b_prime=0.03, f_c=0.0), dict(b=0.2, b_prime=0.05, f_c=-0.1),
             dict(b=0.0, b_prime=0.0, f_c=0.15), dict(b=0.41, b_prime=0.0, f_c=0.0),
             dict(b=0.0, b_prime=0.0, f_c=-0.21),
             # b, b', f_c would allow 00, reversibility does not
             dict(b=0.01, b_prime=0.01, f_c=0.01, v=0.08), dict(b=0.01, b_prime=0.01, f_c=0.01, v=0.31),
             dict(b=0.01, b_prime=0.01, f_c=0.01, v=0.6),
             dict(b=0.01, b_prime=0.01, f_c=0.01, f_0=-0.03), dict(b=0.01, b_prime=0.01, f_c=0.01, c=0.06),
             dict(b=0.15, b_prime=0.01, f_c=0.01, v=0.2, f_0=0.02)]
    for fig in cases:
        _set_figures(st, **fig)
        want, why = _expected_class(fig)
        got = classing(st, 100.0)["+"]
        assert (got["class"], sorted(got["limited_by"])) == (want, sorted(why)), fig
        assert classify(st, 100.0) == {"+": want}
    # a bad step below 10 % of full scale (resolution unknown) does not count; at 10 % it does
    _set_figures(st, b_prime=0.0, f_c=0.0)
    st.figures["b"] = np.where(st.loads < 21.0, 5.0, 0.02)
    assert classify(st, 250.0) == {"+": "00"}  # 20 < 25 = 10 % of 250
    assert classify(st, 200.0) == {"+": "none"}  # 20 = 10 % of 200


def test_table_3_caps_the_class_by_the_reference_uncertainty(hand_set):
    _, calib = hand_set
    st = component_steps(calib, 0)
    _set_figures(st, b=0.01, b_prime=0.01, f_c=0.01)
    for ref in (0.002, 0.01, 0.015, 0.02, 0.05, 0.08, 0.1, 0.2):
        want, why = _expected_class({}, ref)
        got = classing(st, 100.0, reference_uncertainty=ref)["+"]
        assert (got["class"], got["limited_by"]) == (want, why), ref
    assert classify(st, 100.0, reference_uncertainty=0.05) == {"+": "1"}
    assert classify(st, 100.0, reference_uncertainty=0.002) == {"+": "00"}


def test_class_range_starts_at_the_resolution_limit(hand_set):
    _, calib = hand_set
    st = component_steps(calib, 0)
    # deflections grow ~0.0133 per unit load: the 20 step deflects ~0.27 output units
    slope = float(np.mean(np.abs(st.mean) / np.abs(st.loads)))
    _set_figures(st, b_prime=0.0, f_c=0.0)
    st.figures["b"] = np.where(st.loads < 21.0, 0.3, 0.01)  # class 1 at the 20 step, 00 above
    # r such that 4000 r lies between the 20 and 40 steps' deflections, 1000 r below 20's:
    # class 00's range starts above the bad step, and 00 holds there
    r = 30.0 * slope / 4000.0
    got = classing(st, 100.0, r)["+"]
    assert got["class"] == "00" and got["from"] == pytest.approx(4000 * r / slope)
    # a finer resolution puts the 20 step into every class's range: b = 0.3 % there is class 2
    got = classing(st, 100.0, 10.0 * slope / 4000.0)["+"]
    assert got["class"] == "2" and got["limited_by"] == ["b"]
    # a resolution so coarse no step reaches 500 r: no class, for want of resolution
    got = classing(st, 100.0, 1000.0 * slope / 500.0)["+"]
    assert got == {"class": "none", "limited_by": ["resolution"], "from": pytest.approx(1000.0)}


def test_a_timed_hold_gives_creep_and_is_not_a_return(hand_set):
    table, _ = hand_set
    rows = []
    for rep in (1, 2):
        for axis, gain in zip("xyz", (0.0133, -0.0128, 0.008), strict=True):
            # 0, 50, 100 (held: read at 30 s and 300 s), 50, 0; times in seconds, monotonic
            loads, times = [0, 50, 100, 100, 50, 0], [0, 60, 120, 390, 450, 510]
            creep = 3e-4 * rep * np.sign(gain)
            for i, f in enumerate(loads):
                u = [0.01, 0.02, 0.03]
                a = "xyz".index(axis)
                u[a] += gain * f + (creep if i == 3 else 0.0) + (1e-4 if i == 4 else 0.0)
                rows.append((rep, axis, *(f if b == axis else 0.0 for b in "xyz"), *u, times[i]))
    t = pd.DataFrame(rows, columns=["repetition", "axis", "fx", "fy", "fz", "ux", "uy", "uz", "t"])
    calib = from_table(t.drop(columns="t"), replace(load_config(), min_repetitions=1, zero="rows"))
    times = pd.Series(t["t"].to_numpy(), index=calib.points.index)
    for a, gain in enumerate((0.0133, -0.0128, 0.008)):
        st = component_steps(calib, a, times)
        top = list(st.loads).index(100.0)
        # c = 100 (i_300 - i_30) / X_N, the largest over repetitions (rep 2's)
        assert st.figures["c"][top] == pytest.approx(100 * 6e-4 * np.sign(gain) / abs(gain * 100),
                                                    rel=1e-9)
        # the hold is not a way back: v only at 50, from the 1e-4 lift on the way down
        assert np.isnan(st.figures["v"][top])
        assert st.figures["v"][list(st.loads).index(50.0)] == pytest.approx(100 * 1e-4 / abs(gain * 50))
    assert np.isnan(component_steps(calib, 0).figures["c"]).all()  # no times, no creep


def test_budget_adds_the_contributions_in_quadrature(hand_set):
    table, calib = hand_set
    st = component_steps(calib, 1)
    r = resolution(calib, 1)
    u_model = np.linspace(0.01, 0.05, st.loads.size)
    drift = np.linspace(1e-4, 3e-4, st.loads.size)
    b = budget(st, u_model, 0.04, r, 2e-5, drift)
    up, down, zero = _readings(table, "y")
    # the zero drift of the sweep: the largest |i_f - i_0| over repetitions, in volts
    i_drift = max(abs(i_f - i_0) for i_0, i_f, _ in zero.values())
    for j, f in enumerate(st.loads):
        xs = [up[rep][f] for rep in sorted(up)]
        mean = sum(xs) / len(xs)
        s = math.sqrt(sum((x - mean) ** 2 for x in xs) / (len(xs) - 1))
        back = [abs(down[rep][f] - up[rep][f]) / abs(up[rep][f]) for rep in sorted(up) if f in down[rep]]
        w = {"reference": 0.04 / 100 / 2,
             "reproducibility": s / math.sqrt(len(xs)) / abs(mean),
             "repeatability": abs(xs[1] - xs[0]) / abs((xs[0] + xs[1]) / 2) / (2 * math.sqrt(3)),
             "resolution": math.sqrt(2 * (r / (2 * math.sqrt(3))) ** 2) / abs(mean),
             "reversibility": (max(back) if back else 0.0) / math.sqrt(3),
             "interpolation": abs(st.figures["f_c"][j]) / 100 / math.sqrt(3),
             # per step: the drift of the zero relative to this step's deflection
             "zero": i_drift / abs(mean) / math.sqrt(3),
             "temperature": 2e-5,
             "drift": drift[j] / math.sqrt(3),
             "model": u_model[j] / abs(f)}
        for k, v in w.items():
            assert b[k][j] == pytest.approx(v, rel=1e-9), k
        wc = math.sqrt(sum(v * v for v in w.values()))
        assert b["U"][j] == pytest.approx(2 * wc * abs(f), rel=1e-9)
    # the zero term at the smallest step is the top step's times X_N / X_small (~5 here)
    assert b["zero"][0] / b["zero"][-1] == pytest.approx(abs(st.mean[-1] / st.mean[0]), rel=1e-12)
    assert b["zero"][0] > 4 * b["zero"][-1]


def test_temperature_term_from_a_temperature_column():
    from fsdecouple.evaluation.budget import temperature_term
    # every deflection is (1 + K_T (T - 21.5)) times its own, K_T = 2e-4 per kelvin; the
    # temperature runs from 20 to 23 °C over the calibration, and the readings scatter
    # by 1e-6 V (~1e-5 of a deflection): K_T comes back within a few percent
    rng = np.random.default_rng(5)
    rows, temps = [], []
    for rep in (1, 2, 3):
        for axis, gain in zip("xyz", (0.0133, -0.0128, 0.008), strict=True):
            for f in LOADS:
                t = 20.0 + 3.0 * len(rows) / (3 * 3 * len(LOADS) - 1)
                u = [0.01 + rng.normal(0, 1e-6) for _ in range(3)]
                u["xyz".index(axis)] += gain * f * (1 + 2e-4 * (t - 21.5))
                rows.append((rep, axis, *(f if b == axis else 0.0 for b in "xyz"), *u))
                temps.append(t)
    table = pd.DataFrame(rows, columns=["repetition", "axis", "fx", "fy", "fz", "ux", "uy", "uz"])
    calib = from_table(table, replace(load_config(), min_repetitions=1, zero="rows"))
    assert temperature_term(calib, component_steps(calib, 0)) is None  # no column: no term
    calib = replace(calib, points=calib.points.assign(temperature=temps))
    for a in range(3):
        got = temperature_term(calib, component_steps(calib, a))
        assert got == pytest.approx(2e-4 * 3.0 / (2 * math.sqrt(3)), rel=0.05)


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
def certified(calib, sim_model_file):
    """The session's `fsdecouple fit` of the simulated set (the model fsdecouple.fit makes
    of it too: tests/evaluation/test_one_fit.py), and its certificate."""
    model = load_model(sim_model_file)
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
    # one repetition: the verdict holds out each load level in turn (20 s of CPU at the
    # default tolerance); at Table 2's (as a config writes it) 4x less, and the figures
    # the certificate leaves out are the point
    svr = replace(settings.svr, tolerance=1e-3)
    model = calibrate(one, replace(settings, min_repetitions=1, svr=svr))
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


@pytest.fixture(scope="module")
def quiet_sensor(tmp_path_factory):
    """The paper's sensor with 1 uV noise, swept out and back with a 0.02 % lag, and
    without: b, b' and f_c near class 00 (Table 2), so v and Table 3 decide."""
    from fsdecouple.data.calibration import load_calibration
    from fsdecouple.sim.simulate import SimulatedSensor, simulate

    out = {}
    for name, hysteresis in (("back", 0.0002), ("plain", None)):
        path = tmp_path_factory.mktemp(name)
        simulate(path, seed=1, sensor=SimulatedSensor(noise=1e-6), hysteresis=hysteresis)
        calib = load_calibration(path / "calibration", load_config())
        out[name] = (calib, calibrate(calib, load_config()))
    return out


def _best_by(metric: str, values) -> str:
    """The best class of TABLE_2 whose ``metric`` limit every value keeps."""
    col = ("b", "b_prime", "f_c", "f_0", "v", "c").index(metric)
    for cls in ORDER:
        if all(abs(v) <= TABLE_2[cls][col] for v in values):
            return cls
    return "none"


@pytest.mark.slow  # two simulated calibrations, fitted with their verdicts
def test_reversibility_limits_the_class_of_a_sensor_swept_out_and_back(quiet_sensor):
    calib, model = quiet_sensor["back"]
    doc = certificate(model, calib, settings=replace(
        model.settings, lab=replace(model.settings.lab, reference_uncertainty=0.002)))
    recs = pd.DataFrame(doc["records"])
    v = recs[recs["metric"] == "v"]
    assert len(v) and (v["value"] >= 0).all()  # ISO 376's |X' - X| / X
    rank = {c: i for i, c in enumerate((*ORDER, "none"))}
    limited = 0
    for c in doc["classes"]:
        sign = 1 if c["sign"] == "+" else -1
        mine = v[(v["axis"] == c["axis"]) & (np.sign(v["load"]) == sign)
                 & (v["load"].abs() >= c["from"] * (1 - 1e-12))]
        allowed = _best_by("v", mine["value"])
        assert rank[c["class"]] >= rank[allowed], c  # no better than v allows
        # b, b' and f_c alone would allow a better class: v is what limits it
        others = recs[(recs["axis"] == c["axis"]) & (np.sign(recs["load"]) == sign)]
        by_rest = max((_best_by(m, others[others["metric"] == m]["value"])
                       for m in ("b", "b_prime", "f_c")), key=rank.get)
        if rank[by_rest] < rank[c["class"]]:
            assert "v" in c["limited_by"], c
            limited += 1
    assert limited  # the lag of 0.02 % of full scale costs some component its class


@pytest.mark.slow
def test_table_3_caps_the_sensor_without_hysteresis_at_class_1_by_default(quiet_sensor):
    calib, model = quiet_sensor["plain"]
    doc = certificate(model, calib)  # reference_uncertainty 0.05 % (the default)
    assert not any(r["metric"] == "v" for r in doc["records"])
    assert {c["class"] for c in doc["classes"]} == {"1"}
    assert all(c["limited_by"] == ["reference"] for c in doc["classes"])
    fine = replace(model.settings, lab=replace(model.settings.lab, reference_uncertainty=0.002))
    assert {c["class"] for c in certificate(model, calib, settings=fine)["classes"]} == {"00"}


@pytest.mark.slow
def test_a_config_silent_on_zero_is_the_one_fit_was_given(quiet_sensor):
    """fit zeroes sweeps out and back by zero: fit on its own; the same config (no
    zero key) is then the model's, and only a zero the config states is compared."""
    calib, model = quiet_sensor["back"]
    assert model.settings.zero == "fit" and load_config().zero is None
    certificate(model, calib, settings=load_config())  # not refused
    with pytest.raises(InputError, match="the config's zero is not the model's"):
        check_matches(model, calib, "m.json", replace(load_config(), zero="rows"))


def test_the_set_must_be_the_fitted_one_by_name_and_repetition(certified, calib):
    model, _ = certified
    files = list(calib.files)
    (p1, h1), (p6, h6) = files[0], files[-1]
    folder = str(p1).rsplit("/", 1)[0]
    cases = {
        # a copy of rep1.csv saved as rep7.csv: every digest is the model's
        "rep7.csv is not a file the model was fitted on: its content is rep1.csv's":
            [*files, (f"{folder}/rep7.csv", h1)],
        "rep9.csv is not a file the model was fitted on: its content is rep6.csv's":
            [*files[:-1], (f"{folder}/rep9.csv", h6)],
        "the model was fitted on rep6.csv too, which it lacks": files[:-1],
        "rep6.csv is not the file the model was fitted on under that name":
            [*files[:-1], (p6, "0" * 64)],
    }
    for message, given in cases.items():
        with pytest.raises(InputError, match=message.replace(".", r"\.")):
            check_matches(model, replace(calib, files=tuple(given)), "m.json")
    # the same files, but a repetition fewer or more: the labels differ
    with pytest.raises(InputError, match="it lacks repetition 6"):
        check_matches(model, calib.subset([1, 2, 3, 4, 5]), "m.json")
    more = replace(calib, points=calib.points.assign(
        repetition=calib.points["repetition"].replace({6: 7})))
    with pytest.raises(InputError, match="it has repetition 7"):
        check_matches(model, more, "m.json")
    check_matches(model, calib, "m.json")  # the fitted set itself passes


def test_drift_between_calibrations_from_compare_json_or_the_config():
    from fsdecouple.evaluation.certificate_doc import check_drift_document, drift_fractions
    loads = np.array([-100.0, -50.0, 50.0, 100.0])
    doc = {"format": "fsdecouple.drift", "components": {"x": {"force_max_pct": 0.2}},
           "en_steps": [{"axis": "x", "load": -100.0, "F_old": -100.0, "F_new": -100.3},
                        {"axis": "x", "load": 100.0, "F_old": 100.1, "F_new": 100.0},
                        {"axis": "y", "load": 100.0, "F_old": 0.0, "F_new": 9.0}]}
    d, source = drift_fractions(check_drift_document(doc, "c.json"), None, "x", loads, 100.0)
    # |F_old - F_new| / |L|, straight between the two steps compare gives: 0.3 at -100, 0.1 at 100
    assert d == pytest.approx([0.3 / 100, 0.25 / 50, 0.15 / 50, 0.1 / 100])
    assert "compare" in source
    no_steps = {**doc, "en_steps": None}
    d, _ = drift_fractions(no_steps, None, "x", loads, 100.0)  # 0.2 % of 100 = 0.2 at every step
    assert d == pytest.approx(0.2 / np.abs(loads))
    d, source = drift_fractions(None, 0.03, "x", loads, 100.0)
    assert d == pytest.approx(np.full(4, 3e-4)) and source == "config drift"
    assert drift_fractions(None, None, "x", loads, 100.0)[1] is None
    with pytest.raises(InputError, match="c.json: not the output of 'fsdecouple compare --json'"):
        check_drift_document({"format": "fsdecouple.certificate"}, "c.json")


def test_creep_times_are_read_from_the_files_row_by_row(tmp_path):
    """A set on disk whose sweeps hold their top load, read 30 s and 300 s after it was
    applied, dated by a column the config names; blank lines keep their row numbers."""
    from fsdecouple.data.calibration import load_calibration
    from fsdecouple.evaluation.creep import creep_times

    folder = tmp_path / "calibration"
    folder.mkdir()
    loads, times = [0, 50, 100, 100, 50, 0], [0.0, 60.0, 120.0, 390.0, 450.0, 510.0]
    lift = {1: 2e-4, 2: 5e-4}  # i_300 - i_30 of each repetition's sweeps [V]
    for rep in (1, 2):
        lines = ["axis,fx,fy,fz,ux,uy,uz,seconds"]
        t0 = 0.0
        for axis, gain in zip("xyz", (0.0133, -0.0128, 0.008), strict=True):
            for i, f in enumerate(loads):
                u = [0.01, 0.02, 0.03]
                u["xyz".index(axis)] += gain * f + (lift[rep] if i == 3 else 0.0)
                fs = [f if b == axis else 0 for b in "xyz"]
                lines.append(f"{axis},{fs[0]},{fs[1]},{fs[2]},{u[0]!r},{u[1]!r},{u[2]!r},"
                             f"{t0 + times[i]}")
            t0 += 600.0
            lines.append("")  # a blank line between sweeps: rows still count it
        (folder / f"rep{rep}.csv").write_text("\n".join(lines) + "\n")
    config = tmp_path / "c.yaml"
    config.write_text("min_repetitions: 1\nzero: rows\ncreep: {column: seconds}\n")
    settings = load_config(config)
    calib = load_calibration(folder, settings)
    times = creep_times(calib, settings)
    assert times is not None and np.isfinite(times).all()
    for a, gain in enumerate((0.0133, -0.0128, 0.008)):
        st = component_steps(calib, a, times)
        top = list(st.loads).index(100.0)
        # c = 100 (i_300 - i_30) / |X_N|, the larger repetition's (rep 2)
        assert st.figures["c"][top] == pytest.approx(100 * 5e-4 / abs(gain * 100), rel=1e-6)
    # the same readings dated 200 s apart are no 30 s / 300 s pair: no creep
    for f in folder.glob("*.csv"):
        f.write_text(f.read_text().replace(",390.0\n", ",320.0\n").replace(",990.0\n", ",920.0\n")
                     .replace(",1590.0\n", ",1520.0\n"))
    calib = load_calibration(folder, settings)
    assert np.isnan(component_steps(calib, 0, creep_times(calib, settings)).figures["c"]).all()


@pytest.mark.slow  # a fit with the held-out verdict: seconds of CPU; the not-slow run stays under a minute
def test_the_terminal_view_shows_the_temperature_terms(certified):
    """The certificate's document holds a temperature model's terms (its HTML and PDF show
    them); its terminal view left them out."""
    import io

    from rich.console import Console

    from fsdecouple.core.temperature import TemperatureTerms
    from fsdecouple.reporting.certificate_html import certificate_tables

    def console_text(tables) -> str:
        console = Console(record=True, width=100, file=io.StringIO(), markup=False)  # as the CLI
        for t in tables:
            console.print(t)
        return console.export_text()

    model, doc = certified
    terms = TemperatureTerms(3, 25.0, np.array([-8.5e-4, 8.7e-4, -7.2e-4]),
                             np.array([-1.26e-4, 1.27e-4, 1.43e-4]), "degC", (14.82, 35.1))
    text = console_text(certificate_tables({**doc, "temperature": terms.to_dict(["ux", "uy", "uz"])}))
    assert "Temperature terms (T0 = 25 degC, calibrated 14.82 .. 35.1 degC)" in text
    assert "-0.00085" in text and "+127.0" in text and "g [ppm/K]" in text
    assert "Temperature terms" not in console_text(certificate_tables(doc))


def test_resolution_is_the_files_step_through_a_scale():
    """Whole ADC counts read with scale: 2.5e-7 (counts to volts) gave r = 1e-8 V, the
    power of ten the scaled numbers happen to be multiples of: 25 times too fine a
    resolution term and class range.  It is one count, 2.5e-7 V."""
    from fsdecouple.data.calibration import load_calibration

    root = Path(__file__).resolve().parents[2]
    counts = load_config(root / "configs" / "loadcell.yaml")
    volts = replace(counts, scale={**counts.scale, **dict.fromkeys(counts.layout.outputs, 2.5e-7)})
    data = root / "sample_data" / "loadcell" / "calibration.csv"
    a, b = load_calibration(data, counts), load_calibration(data, volts)
    for i in range(3):
        assert resolution(a, i) == 1.0
        assert resolution(b, i) == pytest.approx(2.5e-7, rel=1e-12)


def test_deflections_out_and_back_start_from_the_zero_before_their_series(tmp_path):
    """A sweep -100 .. 100 .. -100 N with a 0.1 % lag reads zero twice; deflections from the
    mean of the two put half the lag into every step, and f_c (a cubic without constant
    term) read it as 0.2 % of interpolation error at +-10 N on a noise-free sensor."""
    from fsdecouple.data.calibration import load_calibration
    from fsdecouple.sim.simulate import SimulatedSensor, simulate

    simulate(tmp_path / "s", seed=1, sensor=SimulatedSensor(noise=1e-7), hysteresis=0.001,
             repetitions=2)
    calib = load_calibration(tmp_path / "s" / "calibration",
                             replace(load_config(), min_repetitions=1, zero="fit"))
    st = component_steps(calib, 0)
    # each series from the zero read before it, the lag constant along it; -100 N is read
    # first with no zero before it, and again at the end of the last series: that one
    assert np.abs(st.figures["f_c"]).max() < 0.005
    assert np.nanmax(st.figures["v"]) > 0.4  # the lag is there, as reversibility (0.48 % at 10 N)
