"""``extrapolation: tangent|kernel``: chi beyond its calibrated input range.

The tangent side is checked against finite differences of the kernel side, the
fast paths against the exact one, kernel models against the kernel sum as it was
evaluated before the option existed, and the gain against a simulated sensor's
true forces beyond full scale.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from conftest import FAST_SVR, ROOT, SAMPLE, assert_one_line_error, invoke

from fsdecouple import load_calibration, load_config, load_model
from fsdecouple.core.decouple import PROMISE
from fsdecouple.core.kernel import rbf_sum
from fsdecouple.core.model import Chi
from fsdecouple.core.modelfile import model_from_dict, model_to_dict, save_model
from fsdecouple.errors import ConfigError
from fsdecouple.fitting.fit import fit
from fsdecouple.logs.apply import apply_file
from fsdecouple.schema import check_extrapolation
from fsdecouple.sim.simulate import SimulatedSensor, simulate, simulate_task

GOLDEN = ROOT / "tests" / "fixtures" / "golden" / "model-v2.json"


@pytest.fixture(scope="module")
def tangent(sample_model):
    """The suite's ``fit sample_data/calibration`` (no config: the default settings), read
    from its file: the same chi as an in-process fit of the sample, without fitting again."""
    assert load_config().extrapolation == "tangent"  # the default of new fits
    model = load_model(sample_model)
    assert model.settings.extrapolation == "tangent"
    return model


@pytest.fixture(scope="module")
def kernel():
    """The sample fitted with extrapolation: kernel, at Table 2's libsvm tolerance: its
    tests check what a chi is beyond the range and what the file keeps, whatever the
    solver's last digits (~1 s of CPU -> ~0.3 s)."""
    settings = load_config(extrapolation="kernel", tolerance=1e-3)
    return fit(load_calibration(SAMPLE / "calibration", settings), settings)


def beyond(model, n: int, reach: float, seed: int = 0) -> np.ndarray:
    """Rows spread over the calibrated range widened by ``reach`` of its span each side."""
    r = np.asarray(model.calibrated_range)
    span = r[:, 1] - r[:, 0]
    rng = np.random.default_rng(seed)
    return rng.uniform(r[:, 0] - reach * span, r[:, 1] + reach * span, (n, len(span)))


# --- continuity ----------------------------------------------------------------------


@pytest.fixture(scope="module")
def scaled():
    """Kernel inputs and targets in full-scale units: input_scale and output_scale != 1
    (at Table 2's libsvm tolerance: the continuity at the edges holds for any chi)."""
    settings = load_config(scaling="full_scale", tolerance=1e-3)
    return fit(load_calibration(SAMPLE / "calibration", settings), settings)


@pytest.mark.parametrize("which", ["tangent", pytest.param("scaled", marks=pytest.mark.slow)])
def test_tangent_is_continuous_in_value_and_slope_at_the_range_edges(which, request):
    model = request.getfixturevalue(which)
    h = 1e-4  # as test_checks: roundoff ~1e-16 sum|c| / h against truncation h^2 chi''' / 3
    for c in model.chi.values():
        assert c.extrapolation == "tangent" and (which == "tangent" or c.input_scale != 1.0)
        lo, hi = c.input_range
        for edge, out in ((lo, -1.0), (hi, 1.0)):
            inward = edge - out * h * np.arange(3)  # chi itself, inside the range only
            # the kernel side's slope, one-sided second order: (3 f0 - 4 f1 + f2) / 2h
            f0, f1, f2 = c(inward)
            kernel_side = out * (3 * f0 - 4 * f1 + f2) / (2 * h)
            # the tangent side: chi's own values just and far beyond the edge
            d = 0.2 * (hi - lo)
            near, far = c(np.array([np.nextafter(edge, out * np.inf), edge + out * d]))
            tangent_side = (far - f0) / (out * d)
            assert near == pytest.approx(f0, abs=1e-12), c.name
            assert tangent_side == pytest.approx(kernel_side, abs=1e-6), c.name
            # and it is a straight line, not the kernel sum (which bends back to -rho)
            mid = c(np.array([edge + out * d / 2]))[0]
            assert mid == pytest.approx((f0 + far) / 2, abs=1e-12)
        far_out = hi + 2 * (hi - lo)
        assert abs(c(np.array([far_out]))[0] - c.kernel(np.array([far_out]))[0]) > 1e-4, c.name


def test_kernel_chi_is_the_kernel_sum_everywhere(kernel):
    for c in kernel.chi.values():
        assert c.extrapolation == "kernel" and c.edges is None
        u = np.linspace(c.input_range[0] - 3, c.input_range[1] + 3, 501)
        np.testing.assert_array_equal(c(u), c.kernel(u))


def test_nan_stays_nan_and_a_chi_without_range_is_not_continued(tangent):
    c = tangent.chi["xy"]
    assert np.isnan(c(np.array([np.nan]))).all()
    bare = Chi("xy", c.gamma, c.support_vectors, c.dual_coef, c.rho, extrapolation="tangent")
    assert bare.edges is None
    np.testing.assert_array_equal(bare(np.array([-9.0, 9.0])), bare.kernel(np.array([-9.0, 9.0])))


# --- every path agrees beyond the range -----------------------------------------------


@pytest.mark.slow  # over ~0.6 s: the not-slow run stays under a minute
@pytest.mark.parametrize("refine", [0, 3])
def test_fast_paths_equal_the_exact_path_beyond_the_range(tangent, refine):
    """Rows up to 60 % of the span past the range: in the tables' margin and past them."""
    u = beyond(tangent, 20_000, 0.6)
    exact = tangent.decouple(u, exact=True, refine=refine)
    covered = np.ones(len(u), bool)
    fast = tangent.fast_decoupler().decouple(u, covered=covered, refine=refine)
    assert 0.2 < covered.mean() < 0.9  # both: rows the tables serve and rows they do not
    ok = np.isfinite(exact).all(axis=1)
    assert np.array_equal(ok, np.isfinite(fast).all(axis=1)) and ok.mean() > 0.9
    bound = PROMISE * np.asarray(tangent.settings.full_scale)  # as test_fast: 1e-9 F.S.
    assert (np.abs(fast[ok] - exact[ok]) <= bound).all()
    # the one-vector function, a Python call a row (~0.6 ms with refine 3): on 500 rows,
    # the tables' and the tangents' both (2000 cost 1.3 s of CPU)
    one = tangent.decoupler(refine=refine)
    n = 500
    assert 0.1 < covered[:n].mean() < 0.9
    got = np.array([one(*row) for row in u[:n].tolist()])
    np.testing.assert_allclose(got, fast[:n], rtol=0, atol=1e-12 * np.abs(fast[:n]).max())


def test_tables_of_a_tangent_model_are_exact_straight_lines_beyond_the_range(tangent):
    """The range's ends are knots, so a Hermite table reproduces the line to rounding."""
    for c in tangent.chi.values():
        s, (lo, hi) = c.surrogate, c.input_range
        x = np.concatenate([np.linspace(s.lo, lo, 1000), np.linspace(hi, s.hi, 1000)[:-1]])
        np.testing.assert_allclose(s(x), c(x), rtol=0, atol=1e-13)
        assert s.covers(np.array([lo, hi])).all()


def test_apply_keeps_status_extrapolated_and_uses_the_tangent(tangent, tmp_path):
    u = beyond(tangent, 300, 0.3, seed=1)
    log = tmp_path / "log.csv"
    pd.DataFrame(u, columns=["ux", "uy", "uz"]).to_csv(log, index=False)
    apply_file(tangent, log, tmp_path / "f.parquet")
    table = pq.read_table(tmp_path / "f.parquet").to_pandas()
    lim = tangent.extrapolation_limits()
    outside = ((u < lim[:, 0]) | (u > lim[:, 1])).any(axis=1)
    assert outside.any() and (~outside).any()
    np.testing.assert_array_equal(table["status"] == "extrapolated", outside)
    np.testing.assert_allclose(table[["fx", "fy", "fz"]].to_numpy(), tangent.decouple(u, exact=True),
                               rtol=0, atol=1e-7)


# --- kernel: today's output, bit for bit ---------------------------------------------------


def _kernel_sum_as_before(self, u):
    """Chi.__call__ as it was before extrapolation existed."""
    x = np.asarray(u, dtype=float) / self.input_scale
    return self.output_scale * rbf_sum(x, self.support_vectors, self.dual_coef, self.gamma, -self.rho)


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_old_model_file_reads_as_kernel_and_applies_bit_for_bit_as_before(tmp_path, monkeypatch,
                                                                          tangent):
    model = load_model(GOLDEN)
    assert "extrapolation" not in json.loads(GOLDEN.read_text())["settings"]
    assert model.settings.extrapolation == "kernel" and model.settings.refine == 0
    assert all(c.extrapolation == "kernel" for c in model.chi.values())
    u = beyond(model, 5000, 0.6, seed=2)  # in the tables, in their margin and past them
    u[::97] = np.nan
    log = tmp_path / "log.csv"
    pd.DataFrame(u, columns=["ux", "uy", "uz"]).to_csv(log, index=False)
    apply_file(model, log, tmp_path / "now.parquet")
    monkeypatch.setattr(Chi, "__call__", _kernel_sum_as_before)
    before = load_model(GOLDEN)  # tables and evaluators as they were: only Chi changed
    apply_file(before, log, tmp_path / "before.parquet")
    now, then = (pq.read_table(tmp_path / f"{n}.parquet").to_pandas() for n in ("now", "before"))
    pd.testing.assert_frame_equal(now, then, check_exact=True)
    assert (now["status"] == "extrapolated").sum() > 1000
    # beyond the range a tangent model's forces differ by far more: the comparison can fail
    # (the module's fit of the sample at the default settings, tangent's)
    monkeypatch.undo()
    assert np.nanmax(np.abs(tangent.decouple(u) - model.decouple(u))) > 0.1


def test_the_mode_survives_the_model_file(tangent, kernel, tmp_path):
    for model, mode in ((tangent, "tangent"), (kernel, "kernel")):
        path = tmp_path / f"{mode}.json"
        save_model(model, path)
        assert json.loads(path.read_text())["settings"]["extrapolation"] == mode
        back = load_model(path)
        assert back.settings.extrapolation == mode
        u = beyond(model, 500, 0.6)
        np.testing.assert_array_equal(back.decouple(u), model.decouple(u))
        refined = back.refined(2)  # apply --refine K keeps the mode
        assert refined.settings.extrapolation == mode == refined.chi["xy"].extrapolation


# --- bad input: one line, exit 2 ------------------------------------------------------------


def test_unknown_mode_is_refused():
    for bad in ("linear", "", None, 1, "Tangent"):
        with pytest.raises(ConfigError, match="extrapolation: expected one of tangent, kernel"):
            check_extrapolation(bad)


def test_cli_unknown_mode_exit_2_and_nothing_written(tmp_path):
    out = tmp_path / "m.json"
    r = invoke(["fit", SAMPLE / "calibration", "-o", out, "--extrapolation", "linear"], code=2)
    assert_one_line_error(r, "--extrapolation", "'linear'", "tangent, kernel")
    cfg = tmp_path / "c.yaml"
    cfg.write_text("extrapolation: quadratic\n")
    r = invoke(["fit", SAMPLE / "calibration", "-o", out, "-c", cfg], code=2)
    assert_one_line_error(r, "c.yaml: extrapolation", "'quadratic'")
    assert not out.exists()


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_cli_fit_records_the_mode(tmp_path):
    (tmp_path / "fast.yaml").write_text(FAST_SVR)  # the mode is recorded, whatever the solver
    for args, mode in (([], "tangent"), (["--extrapolation", "kernel"], "kernel")):
        out = tmp_path / f"{mode}.json"
        invoke(["fit", SAMPLE / "calibration", "-c", tmp_path / "fast.yaml", "-o", out,
                "--no-verdict", *args])
        assert load_model(out).settings.extrapolation == mode


def test_model_file_with_an_unknown_mode_is_refused(tangent):
    doc = model_to_dict(tangent)
    doc["settings"]["extrapolation"] = "spline"
    from fsdecouple.core.modelfile import content_digest

    doc["integrity"]["digest"] = content_digest(doc)
    with pytest.raises(ConfigError, match="extrapolation: expected one of"):
        model_from_dict(doc, "m.json")


# --- the gain: loads beyond full scale ----------------------------------------------------


@pytest.mark.slow
def test_tangent_beats_kernel_on_loads_up_to_120_percent_of_full_scale(tmp_path):
    """Simulated sensors with known coupling, task loads peaking at 1.2 x full scale.

    Worst axis's RMS force error [% F.S.]: on these seeds the tangent gives
    0.10-0.12, the kernel sum 0.12-0.19 (the floor of 0.5 mV noise is ~0.05).

    Limits from the scatter over seeds 0-23 (this procedure per seed): tangent / kernel
    per seed mean 0.69, sd 0.13, max 0.95 (seed 19; 0.86 for seed 0), below 1 on all
    24; the ratio of the means over three consecutive seeds mean 0.66, sd 0.085, max
    0.84 (0.75 for seeds 0-2).  So per seed at most SEED_LIMIT = 1.2 (the max x 1.25:
    one seed's fit moves between machines) and over the three at most MEAN_LIMIT =
    0.92 (mean + 3 sd, the max x 1.1): the tangent is better on average.

    The fits stop at Table 2's libsvm tolerance (1e-3, a third of the CPU of the
    noise-derived default).  The scatter was derived again at that tolerance over seeds
    0-23: per seed mean 0.691, sd 0.130, max 0.951 (seed 19; 0.855 for seed 0); three
    consecutive seeds mean 0.658, sd 0.085, max 0.841 (0.748 for seeds 0-2).  That is
    the default's scatter to its last printed digit, so the limits stand.
    """
    seed_limit, mean_limit = 1.2, 0.92  # SEED_LIMIT, MEAN_LIMIT above
    sensor = SimulatedSensor()
    worst = {"tangent": [], "kernel": []}
    for seed in range(3):
        simulate(tmp_path / str(seed), seed=seed)
        volts, forces = simulate_task(sensor, seed=seed, reach=1.2)
        u = volts[["ux", "uy", "uz"]].to_numpy()
        u = u - u[:200].mean(axis=0)  # the task's own tare, as apply --tare 200
        f = forces[["fx", "fy", "fz"]].to_numpy()
        assert (np.abs(f).max(axis=0) == pytest.approx(1.2 * np.asarray(sensor.full_scale)))
        # one fit per seed: the chi are the same whatever the mode (it decides only what a
        # chi is beyond its range); each mode's model is that fit with the mode's settings,
        # decoupled on the exact path (the tables' 1e-9 F.S. is far below these figures)
        fast = load_config(tolerance=1e-3)  # Table 2's tolerance: the scatter above
        fitted = fit(load_calibration(tmp_path / str(seed) / "calibration", fast), fast,
                     tables=False)
        for mode in worst:
            settings = load_config(extrapolation=mode)
            model = replace(fitted, settings=settings)
            assert all(c.extrapolation == mode for c in model.chi.values())
            lim = model.extrapolation_limits()
            assert ((u < lim[:, 0]) | (u > lim[:, 1])).any(axis=1).mean() > 0.5
            err = (model.decouple(u, exact=True) - f) / np.asarray(settings.full_scale)
            worst[mode].append(100 * np.sqrt((err ** 2).mean(axis=0)).max())
    t, k = np.array(worst["tangent"]), np.array(worst["kernel"])
    assert (t <= seed_limit * k).all(), worst
    assert t.mean() < mean_limit * k.mean(), worst



def test_show_names_the_modes_the_model_carries(sample_model):
    """An old file shows kernel extrapolation; a new fit shows tangent (``show``'s caption)."""
    old = " ".join(invoke(["show", GOLDEN]).stdout.split())
    new = " ".join(invoke(["show", sample_model]).stdout.split())
    assert "beyond the input range: kernel (extrapolation)" in old
    assert "beyond the input range: tangent (extrapolation)" in new
    assert "zero offsets: rows; refinement steps K = 0" in new
