"""Degenerate but valid calibration data fit without NaN, or fail with a clear error."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from fsdecouple import load_calibration, load_config, load_model
from fsdecouple.core.modelfile import save_model
from fsdecouple.errors import InputError
from fsdecouple.fitting.fit import fit
from fsdecouple.sim.simulate import SimulatedSensor, simulate

ZERO = ((0.0, 0.0, 0.0),) * 3


def fit_and_decouple(tmp_path, sensor):
    simulate(tmp_path, sensor=sensor)
    settings = load_config()
    model = fit(load_calibration(tmp_path / "calibration", settings), settings)
    log = pd.read_csv(tmp_path / "task_voltages.csv")
    u = log[["ux", "uy", "uz"]].to_numpy()
    f = model.decouple(u - u[:200].mean(axis=0))
    truth = pd.read_csv(tmp_path / "task_forces.csv")[["fx", "fy", "fz"]].to_numpy()
    save_model(model, tmp_path / "m.json")
    again = load_model(tmp_path / "m.json")
    np.testing.assert_array_equal(again.decouple(u), model.decouple(u))
    return model, f, truth


def assert_finite_model(model):
    assert np.isfinite(model.k).all()
    for chi in model.chi.values():
        assert np.isfinite(chi.support_vectors).all() and np.isfinite(chi.dual_coef).all()
        assert np.isfinite(chi.rho)
    assert all(np.isfinite(v) for v in model.report.gamma_after.values())


def test_all_zero_coupling_perfectly_linear_sensor(tmp_path):
    """No coupling and no noise: every chi target is 0 (libsvm gets all-zero y)."""
    model, f, truth = fit_and_decouple(tmp_path, SimulatedSensor(amplitude=ZERO, noise=0.0))
    assert_finite_model(model)
    assert np.isfinite(f).all()
    # the data are written to 0.1 uV and 1 mN: that rounding bounds the error
    np.testing.assert_allclose(f, truth, atol=1e-3)
    for chi in model.chi.values():
        assert np.abs(chi(np.linspace(-1.5, 1.5, 50))).max() < 1e-3


def test_noise_free_sensor_with_coupling(tmp_path):
    model, f, truth = fit_and_decouple(tmp_path, SimulatedSensor(noise=0.0))
    assert_finite_model(model)
    assert np.isfinite(f).all() and np.abs(f - truth).max() < 0.75


@pytest.mark.slow  # a fit on twice the points: seconds of CPU; the not-slow run stays under a minute
def test_duplicate_points(tmp_path, sim_dir, model):
    """Every calibration row twice (a copy-paste slip): fits, and barely moves the model."""
    d = tmp_path / "dup"
    d.mkdir()
    for f in (sim_dir / "calibration").glob("*.csv"):
        df = pd.read_csv(f, dtype=str)
        pd.concat([df, df]).to_csv(d / f.name, index=False)
    settings = load_config()
    dup = fit(load_calibration(d, settings), settings)
    once = model  # conftest's: the same set, fitted once a session with the same settings
    assert_finite_model(dup)
    u = pd.read_csv(sim_dir / "task_voltages.csv")[["ux", "uy", "uz"]].to_numpy()
    u = u - u[:200].mean(axis=0)  # inside the calibrated range
    np.testing.assert_allclose(dup.k, once.k, rtol=1e-12)
    # libsvm sees each point twice (weight 2 against the same C): a slightly
    # different optimum, well inside the 0.75 N accuracy of the round trip
    assert np.abs(dup.decouple(u) - once.decouple(u)).max() < 0.5


@pytest.mark.parametrize("channel", ["ux", "uy", "uz"])
def test_constant_channel_fails_clearly(tmp_path, sim_dir, channel):
    """A dead bridge: one voltage column constant everywhere."""
    d = tmp_path / "dead"
    d.mkdir()
    for f in (sim_dir / "calibration").glob("*.csv"):
        df = pd.read_csv(f, dtype=str)
        df[channel] = "0.0123000"
        df.to_csv(d / f.name, index=False)
    settings = load_config()
    axis = channel[1]
    with pytest.raises(InputError, match=f"prime voltage {channel} does not change with f{axis}"):
        fit(load_calibration(d, settings), settings)


def test_the_odd_repetitions_grid_is_the_one_named(tmp_path):
    """Repetition 1 skipped a step of its x sweep: the warning named repetition 2 (the
    first that differed from repetition 1), where five of six agree on another grid."""
    from dataclasses import replace

    from fsdecouple.data.calibration import from_table
    from fsdecouple.sim.simulate import simulate_calibration

    table = simulate_calibration(SimulatedSensor(), repetitions=6, seed=2)
    gone = table.index[(table["repetition"] == 1) & (table["axis"] == "x") & (table["fx"] == 50.0)]
    calib = from_table(table.drop(gone), replace(load_config(), min_repetitions=1))
    said = [w for w in calib.warnings if "different load grid" in w]
    assert len(said) == 1 and said[0].startswith("the x sweep of repetition 1 uses"), said
    assert "than repetition 2 (5 of 6 repetitions share that one)" in said[0]
