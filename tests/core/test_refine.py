"""Second-order refinement: K fixed-point steps on the prime outputs before eq. (11)."""

from __future__ import annotations

import json
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd
import pytest
from conftest import EXACT_TOL, FAST_CONFIG, FAST_SVR, SAMPLE, TABLE_TOL, eq11_from_file, invoke

from fsdecouple import load_config, load_model
from fsdecouple.axes import NamedChi
from fsdecouple.config import Settings, settings_from_dict
from fsdecouple.core import plan as plan_module
from fsdecouple.core.decouple import PROMISE, decouple_exact
from fsdecouple.data.calibration import from_table
from fsdecouple.errors import ConfigError, InputError
from fsdecouple.evaluation.checks import assumption_checks
from fsdecouple.fitting.fit import fit
from fsdecouple.logs.apply import STATUSES, apply_file
from fsdecouple.reporting.advice import refine_advice
from fsdecouple.sim.simulate import SimulatedSensor, simulate_calibration

GOLDEN = SAMPLE.parent / "tests" / "fixtures" / "golden"
LOG = SAMPLE / "task_voltages.csv"


@dataclass(frozen=True)
class TrueChi(NamedChi):
    """The simulator's coupling phi_ab as a chi of the prime output: chi_ab(u) = phi_ab(u / k_b)."""

    sensor: SimulatedSensor
    name: str

    def __call__(self, u):
        return self.sensor.phi(self.name, np.asarray(u) / self.sensor.k[self.input_axis])


def strong_sensor(factor: float) -> SimulatedSensor:
    base = SimulatedSensor()
    return replace(base, amplitude=tuple(tuple(factor * v for v in r) for r in base.amplitude))


def combined_loads(sensor, n, seed=0):
    """Random loads over every axis's calibrated span at once [N]."""
    span = np.array(sensor.load_span) * np.asarray(sensor.full_scale)[:, None]
    return np.random.default_rng(seed).uniform(span[:, 0], span[:, 1], (n, 3))


def test_refinement_with_the_true_chi_solves_eq1(monkeypatch):
    """Noise-free combined loads through eq. (1)-(3): the fixed point is the prime
    output, so K steps recover the loads to rounding, and each step shrinks the
    error at least by the contraction factor (N - 1) max|chi'| (finite differences)."""
    # at 3x coupling the last step of K = 1 exceeds the 1 % F.S. settled test (that
    # row would be not_converged); here every step's error is looked at
    monkeypatch.setattr(plan_module, "REFINE_TOLERANCE", 1.0)
    sensor = strong_sensor(3.0)  # 3x the sample's coupling: the second-order error is large
    chis = [TrueChi(sensor, name) for name in sensor.shapes]
    f = combined_loads(sensor, 5000)
    u = sensor.voltages(f)
    fs = np.asarray(sensor.full_scale)

    def error(k):
        return np.abs(decouple_exact(u, sensor.k, chis, refine=k) - f).max(axis=0) / fs

    slope = 0.0
    for c in chis:  # max |chi'| over 1.5x the calibrated output range, by differences
        x = np.linspace(-1.5, 1.5, 30001) * sensor.full_scale_output[c.input_axis]
        slope = max(slope, float(np.abs(np.diff(c(x)) / np.diff(x)).max()))
    q = 2 * slope
    assert q < 1  # a contraction
    errors = [error(k).max() for k in range(5)]
    assert errors[0] > 1e-3  # eq. (11) alone: a second-order error of 0.1 % F.S. and more
    for e0, e1 in zip(errors, errors[1:], strict=False):
        assert e1 <= q * e0 * 1.0001 + 1e-15
    # at K = 30 only rounding is left (q^30 < 1e-14 of a ~5 % error)
    assert error(30).max() <= 1e-12


def test_k0_is_eq11_on_the_table_and_exact_paths(tmp_path):
    """The refinement leaves eq. (11) as it was: `apply --round-trip` gives the same bytes
    with K from the model (0) and with an explicit `--refine 0`, and those forces are
    eq. (11) written out from the file's own numbers (conftest.eq11_from_file), for the
    table path (model-v2) and the exact kernel sums (model-v1-without-surrogates).

    This was the SHA-256 of those bytes as main printed them at a6bde72.  Forces printed
    to the last bit are not the same on every machine (numpy's exp has its own AVX-512
    loop, elsewhere libm's; numba compiles the table kernel for the host CPU), so the
    bytes are compared on one machine and the forces with eq. (11) to rounding.
    """
    u = pd.read_csv(LOG)[["ux", "uy", "uz"]].to_numpy()
    u = u - u[:200].mean(axis=0)
    for name, tol in (("model-v2.json", TABLE_TOL), ("model-v1-without-surrogates.json", EXACT_TOL)):
        want = eq11_from_file(json.loads((GOLDEN / name).read_text()), u)
        texts = []
        for extra in ([], ["--refine", "0"]):
            out = tmp_path / f"{name}{len(extra)}.csv"
            invoke(["apply", GOLDEN / name, LOG, "-o", out, "--tare", "200", "--round-trip",
                    *extra])
            texts.append(out.read_bytes())
        assert texts[0] == texts[1], name
        got = pd.read_csv(out, dtype=str)  # the text read back by Python's own float()
        assert (got["status"] == "ok").all(), name
        f = got[["fx", "fy", "fz"]].map(float).to_numpy()
        err = np.abs(f - want) / np.array([100.0, 100.0, 150.0])
        assert err.max() <= tol, (name, err.max(axis=0))


def test_refine_zero_is_the_default_on_every_path(model):
    r = model.calibrated_range
    u = np.random.default_rng(3).uniform(1.3 * r[:, 0], 1.3 * r[:, 1], (2000, 3))
    for exact in (False, True):
        np.testing.assert_array_equal(model.decouple(u, exact=exact, refine=0),
                                      model.decouple(u, exact=exact))
    one, one0 = model.decoupler(), model.decoupler(refine=0)
    for v in u[:50].tolist():
        assert one(*v) == one0(*v)


@pytest.mark.slow  # dense points through both paths, several K
def test_fast_and_exact_agree_under_refinement(model):
    """Within the table promise (PROMISE of each full-scale output): the tables' error
    enters p once per step but the contraction shrinks what it carries forward."""
    r = model.calibrated_range
    u = np.random.default_rng(4).uniform(1.2 * r[:, 0], 1.2 * r[:, 1], (100_000, 3))
    u[::50, 2] = 7.5  # outside a table: exact in both
    for k in (1, 3):
        c_fast, c_exact = np.empty(len(u), bool), np.empty(len(u), bool)
        fast = model.decouple(u, refine=k, converged=c_fast)
        exact = model.decouple(u, exact=True, refine=k, converged=c_exact)
        # rows 6x beyond z's range (7.5 V) move by more than the convergence test after
        # one step with the chi solved to the noise (steeper tangents); three settle
        assert (c_fast == c_exact).all() and (k == 1 or c_fast.all())
        assert c_fast[u[:, 2] != 7.5].all()
        diff = np.abs(fast - exact) * np.abs(model.k) / model.full_scale_output
        assert diff[c_fast].max() <= PROMISE  # an unsettled row has no force (NaN) in both
        assert np.isnan(fast[~c_fast]).all() and np.isnan(exact[~c_exact]).all()
        # and refinement does something: far more than the promise
        assert (np.abs(fast - model.decouple(u)) * np.abs(model.k))[c_fast].max() > 1e3 * PROMISE


def _mixed_voltages(model, seed=11):
    r = model.calibrated_range
    u = np.random.default_rng(seed).uniform(r[:, 0], r[:, 1], (300, 3))
    s = model.chi["xy"].surrogate
    u[::9, 1] = s.hi + 0.01  # outside a table at u
    u[5::13, 1] = s.hi - 1e-4  # inside at u, and p may step out of the table
    u[4, 0] = np.nan
    return u


def test_one_vector_path_equals_array_path_bit_for_bit_under_refinement(model):
    u = _mixed_voltages(model)
    fd = model.fast_decoupler()
    for k in (1, 2, 5):
        ref = fd.decouple(u, refine=k, block_rows=64, workers=1)
        one = model.decoupler(refine=k)
        np.testing.assert_array_equal(np.array([one(*v) for v in u.tolist()]), ref)
        np.testing.assert_array_equal(fd.decouple(u, refine=k, block_rows=997, workers=2), ref)
        for a in (0, 9, 100):  # small calls go through the one-vector evaluator
            np.testing.assert_array_equal(model.decouple(u[a:a + 20], refine=k), ref[a:a + 20])


def test_rows_that_do_not_settle_get_nan_and_a_mask_on_every_path(model, monkeypatch):
    """With a tolerance at the median size of the last step of K = 1 (~4e-4 F.S.
    on these points), about half the rows cannot settle: every path flags the same
    rows and gives them NaN, not forces."""
    monkeypatch.setattr(plan_module, "REFINE_TOLERANCE", 4e-4)
    strict = replace(model)  # fresh tables, built with the patched tolerance
    u = _mixed_voltages(model)
    conv = np.empty(len(u), bool)
    f = strict.decouple(u, refine=1, converged=conv)
    assert 0.1 * len(u) < (~conv).sum() < 0.9 * len(u)
    assert np.isnan(f[~conv]).all() and np.isfinite(f[conv]).all()
    one = strict.decoupler(refine=1)
    np.testing.assert_array_equal(np.array([one(*v) for v in u.tolist()]), f)
    conv_exact = np.empty(len(u), bool)
    strict.decouple(u, exact=True, refine=1, converged=conv_exact)
    np.testing.assert_array_equal(conv_exact, conv)


def test_a_diverging_iteration_is_not_converged():
    """chi_xy = chi_yx = 2u: the map p -> u - chi(p) has eigenvalues +-2 and diverges;
    only u = 0, its fixed point, settles."""
    @dataclass(frozen=True)
    class Linear:
        output_axis: int
        input_axis: int
        slope: float

        def __call__(self, u):
            return self.slope * np.asarray(u)

    chis = [Linear(0, 1, 2.0), Linear(1, 0, 2.0), Linear(2, 0, 0.01)]
    u = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, -0.2, 0.3]])
    conv = np.empty(3, bool)
    f = decouple_exact(u, np.ones(3), chis, refine=10, converged=conv)
    np.testing.assert_array_equal(conv, [True, False, False])
    np.testing.assert_array_equal(f[0], 0.0)
    assert np.isnan(f[1:]).all()
    with np.errstate(over="ignore", invalid="ignore"):  # 2^2000 overflows to inf, then nan
        f = decouple_exact(u, np.ones(3), chis, refine=2000, converged=conv)
    np.testing.assert_array_equal(conv, [True, False, False])


def test_apply_marks_rows_that_do_not_settle(tmp_path, sample_model):
    """A model whose chi_xy and chi_yx are made 60x steeper (slopes >> 1/(N - 1)):
    the refined iteration oscillates, those rows get status not_converged and no forces."""
    assert "not_converged" in STATUSES
    model = load_model(sample_model)
    steep = {n: replace(c, output_scale=60 * c.output_scale, surrogate=None) if n in ("xy", "yx")
             else c for n, c in model.chi.items()}
    bad = replace(model, chi=steep).refined(8)
    out = tmp_path / "f.csv"
    summary = apply_file(bad, LOG, out, tare=200)
    df = pd.read_csv(out)
    rows = df["status"] == "not_converged"
    assert summary.status_counts["not_converged"] == rows.sum() > 0
    assert df.loc[rows, ["fx", "fy", "fz"]].isna().all().all()
    assert df.loc[~rows, ["fx", "fy", "fz"]].notna().all().all()
    # the sample model itself, refined: every row settles
    summary = apply_file(model.refined(8), LOG, tmp_path / "g.csv", tare=200)
    assert summary.status_counts["not_converged"] == 0
    assert summary.status_counts["ok"] + summary.status_counts["extrapolated"] == 3000


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_recommended_k_reaches_the_noise_floor_on_a_strongly_coupled_sensor(settings):
    """Fit a simulated sensor with 4x the sample's coupling; the K that fit recommends
    brings the combined-load forces within the simulator's noise (0.5 mV, ~0.04 %
    F.S.) of the fully converged K = 30, which eq. (11) alone (K = 0) is not."""
    sensor = strong_sensor(4.0)
    model = fit(from_table(simulate_calibration(sensor, seed=3), settings), settings)
    advice = refine_advice(assumption_checks(model), 3)
    k = advice["recommended"]
    assert advice["second_order"] > advice["target"] and 1 <= k <= 6
    u = sensor.voltages(combined_loads(sensor, 20_000, seed=2))
    noise = sensor.noise / sensor.full_scale_output.min()
    fs = np.asarray(sensor.full_scale)
    floor = model.decouple(u, refine=30)

    def gap(kk):
        return (np.abs(model.decouple(u, refine=kk) - floor) / fs).max()

    assert gap(0) > 10 * noise
    assert gap(k) <= noise


def test_refine_advice_on_the_sample_model(model):
    advice = refine_advice(assumption_checks(model), 3)
    checks = assumption_checks(model)
    assert advice["second_order"] == max(c.value for c in checks if c.name == "second_order")
    assert advice["recommended"] in (0, 1, 2)


@pytest.mark.slow  # over ~0.8 s: the not-slow run stays under a minute
def test_refine_in_config_and_model_file(tmp_path, sample_fit):
    sample_model = sample_fit[0] / "model.json"
    assert settings_from_dict({"refine": 3}).refine == 3
    assert settings_from_dict({}).refine == 0
    assert "refine" not in Settings().to_dict()  # old model files keep their bytes
    assert "refine" not in json.loads(sample_model.read_text())["settings"]
    cfg = tmp_path / "c.yaml"
    cfg.write_text("refine: 2\n")
    assert load_config(cfg).refine == 2
    out = tmp_path / "m.json"
    (tmp_path / "fast.yaml").write_text(FAST_SVR)  # the solver's last digits are not the point
    res = invoke(["fit", SAMPLE / "calibration", "-c", tmp_path / "fast.yaml", "-o", out,
                  "--refine", "3", "--json"])
    doc = json.loads(res.stdout)
    assert doc["refine"] == 3 and "recommended" in doc["refine_advice"]
    assert json.loads(out.read_text())["settings"]["refine"] == 3
    m = load_model(out)
    assert m.settings.refine == 3
    u = np.array([[0.4, -0.3, -0.6]])
    np.testing.assert_array_equal(m.decouple(u), m.decouple(u, refine=3))
    text = sample_fit[1].stdout  # `fsdecouple fit sample_data/calibration`, once a session
    assert "second-order coupling error (eq. 6)" in text


@pytest.mark.parametrize("value", [-1, 1.5, True, "2", 101, None])
def test_bad_refine_in_config_is_one_line(value):
    with pytest.raises(ConfigError, match=r"refine: expected a whole number of refinement steps"):
        settings_from_dict({"refine": value})


def test_bad_refine_in_python_calls(model):
    with pytest.raises(ConfigError, match="refine"):
        model.decouple(np.zeros((1, 3)), refine=-1)
    with pytest.raises(ConfigError, match="K: expected a whole number") as err:
        model.refined(2.5)
    assert err.value.argument == "refine"  # the CLI names it --refine


@pytest.mark.parametrize("value", ["-1", "1.5", "x", "101"])
def test_bad_refine_on_the_command_line_exits_2_and_writes_nothing(tmp_path, sample_model, value):
    out = tmp_path / "f.csv"
    r = invoke(["apply", sample_model, LOG, "-o", out, "--refine", value], code=2)
    assert "refine" in r.stderr  # one line from the entry point (test_cli's usage errors)
    assert not out.exists()
    m = tmp_path / "m.json"
    r = invoke(["fit", SAMPLE / "calibration", "-o", m, "--refine", value], code=2)
    assert "refine" in r.stderr and not m.exists()
    cfg = tmp_path / "c.yaml"
    cfg.write_text(f"refine: {value}\n")
    r = invoke(["fit", SAMPLE / "calibration", "-o", m, "-c", cfg], code=2)
    assert "refine" in r.stderr and not m.exists()


# --- which option when: --tune with refinement (issue 24) -----------------------------------


def _record(figures, chosen):
    return {"candidates": [{"figure": f} for f in figures], "chosen": chosen}


def test_tune_advice_untuned_from_the_coupling_tuned_from_the_held_out_figures():
    from fsdecouple.reporting.advice import tune_advice

    coupled, weak, diverging = ({"recommended": k} for k in (2, 0, None))
    # untuned: --tune is advised wherever refinement is (eq. 6 above the target)
    assert tune_advice(coupled, None) == {"recommended": True, "basis": "coupling", "gain": None}
    assert not tune_advice(weak, None)["recommended"]
    assert not tune_advice(diverging, None)["recommended"]
    # tuned: the held-out figures decide; the gain is the chosen figure against Table 2's
    t = tune_advice(coupled, _record([0.0026, 0.0021, 0.0020], 2))
    assert t["recommended"] and t["basis"] == "heldout"
    assert t["gain"] == pytest.approx(1 - 0.0020 / 0.0026)
    kept = tune_advice(coupled, _record([0.0026, 0.0030], 0))
    assert not kept["recommended"] and kept["gain"] == 0.0


def test_fit_line_recommends_tune_with_refinement():
    from fsdecouple.cli.model import _refine_line
    from fsdecouple.reporting.advice import tune_advice

    base = {"second_order": 0.004, "chi": "yx", "slope": 0.1, "target": 5e-4, "recommended": 2}
    untuned = {**base, "tune": tune_advice(base, None)}
    assert "recommended: --tune --refine 2 (" in _refine_line(untuned, 0)
    assert _refine_line(untuned, 3).endswith("recommended: --tune (--tune chooses the SVR "
                                             "settings by held-out error)")
    tuned = {**base, "tune": tune_advice(base, _record([0.0025, 0.0020], 1))}
    line = _refine_line(tuned, 0)
    assert "--tune's choice is 20 % below Table 2 on held-out points" in line
    assert line.endswith("recommended: --refine 2 (brings it within 0.05 % F.S.)")
    assert "recommended" not in _refine_line(tuned, 3)
    kept = {**base, "tune": tune_advice(base, _record([0.0025, 0.0030], 0))}
    assert "--tune kept Table 2" in _refine_line(kept, 3)
    weak = {**base, "recommended": 0}
    weak["tune"] = tune_advice(weak, None)
    assert "--tune" not in _refine_line(weak, 0)  # eq. (11) as written is enough: no advice
    # a set tuning cannot run on (one loaded point per sweep) was told to --tune, which then
    # failed; a linear model was told to refine and tune, both refused for it
    few = {**base, "tune": tune_advice(base, None, can_tune=False)}
    assert few["tune"]["recommended"] is False
    assert _refine_line(few, 0).endswith("recommended: --refine 2 (brings it within 0.05 % F.S.)")
    linear = {**base, "tune": tune_advice(base, None, linear=True)}
    assert "recommended" not in _refine_line(linear, 0)


@pytest.mark.slow  # a fit of the sample: ~1 s
def test_fit_prints_and_records_the_tune_advice(tmp_path, sample_fit):
    # the advice comes from the fitted chi, not from the held-out verdict (and not from the
    # solver's last digits: Table 2's tolerance)
    res = invoke(["fit", SAMPLE / "calibration", "-o", tmp_path / "m.json", "--json", "--no-verdict",
                  "-c", FAST_CONFIG])
    doc = json.loads(res.stdout)
    assert doc["refine_advice"]["recommended"] >= 1  # the sample's coupling: 1.1-2.7 %
    assert doc["refine_advice"]["tune"] == {"recommended": True, "basis": "coupling", "gain": None}
    text = sample_fit[1].stdout  # `fsdecouple fit sample_data/calibration`, once a session
    assert "recommended: --tune --refine" in " ".join(text.split())


def test_a_refinement_that_does_not_settle_on_the_calibration_is_named(settings):
    """At 30 % coupling, fit --refine 1 said a valid cell 'makes gamma (eq. 12) ...
    overflow', naming that cell: the unsettled points' NaN forces made gamma NaN."""
    sensor = strong_sensor(12.0)
    settings = replace(settings, min_repetitions=2)
    table = from_table(simulate_calibration(sensor, repetitions=2, seed=5), settings)
    with pytest.raises(InputError, match=r"^refine 1: the second-order refinement does not "
                       r"settle on \d+ of the \d+ calibration points .*use refine 0"):
        fit(table, replace(settings, refine=1, svr=replace(settings.svr, tolerance=1e-3)))


def test_a_linear_model_is_not_refined(sample_model, settings):
    """apply --refine 3 on a linear model was accepted and did nothing; fit --method linear
    --refine 2 stored a K the model never uses."""
    from fsdecouple.evaluation.calibrate import fit as calibrate

    linear = replace(load_model(sample_model), method="linear")
    with pytest.raises(ConfigError, match="refine 3: a linear model decouples by its calibration matrix"):
        linear.refined(3)
    assert linear.refined(0).settings.refine == 0
    with pytest.raises(InputError, match="refine 2: a linear model"):
        calibrate(None, replace(settings, refine=2), method="linear")


def test_cv_refuses_a_refined_row_that_does_not_settle(settings):
    """cv --refine 3 at 30 % coupling printed 'svr-refined worst gamma 0.00 %' (NaN gamma
    records compare as never worse) and then wrote cv.json with NaN: a traceback."""
    from fsdecouple.evaluation.cv import run_cv

    settings = replace(settings, min_repetitions=3, svr=replace(settings.svr, tolerance=1e-3))
    table = from_table(simulate_calibration(strong_sensor(12.0), repetitions=3, seed=5), settings)
    with pytest.raises(InputError, match=r"^refine 3: the second-order refinement does not settle"):
        run_cv(table, settings, folds=[[1, 2]], refine=3)
