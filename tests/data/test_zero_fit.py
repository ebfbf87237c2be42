"""``zero: fit``: each sweep's offsets from all its points (fsdecouple.data.zero.fitted_offsets)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from conftest import SAMPLE, invoke

from fsdecouple import load_model
from fsdecouple.axes import AXES, VOLTAGE_COLUMNS
from fsdecouple.config import Settings, settings_from_dict
from fsdecouple.data.calibration import from_table
from fsdecouple.errors import ConfigError
from fsdecouple.fitting.fit import fit
from fsdecouple.sim.simulate import SimulatedSensor, simulate_calibration

FIT = replace(Settings(), zero="fit")


def _table(sensor, seed=0, reps=6):
    t = simulate_calibration(sensor, repetitions=reps, seed=seed)
    t["file"], t["row"] = "sim.csv", np.arange(len(t)) + 2
    return t


def _noise_free_with_bad_zero_rows(delta: float):
    """A noise-free set whose zero rows read ``delta`` high on every channel.

    The offset of each sweep is then known exactly: the one its loaded rows carry.
    Zero-row correction leaves ``-delta`` on every loaded point; offsets from all
    points should not.
    """
    sensor = replace(SimulatedSensor(), noise=0.0)
    table = _table(sensor)
    zero = (table[["fx", "fy", "fz"]] == 0).all(axis=1)
    table.loc[zero, list(VOLTAGE_COLUMNS)] += delta
    return sensor, from_table(table, Settings()), from_table(table, FIT)


def test_prime_offsets_come_from_every_point():
    """omega through the origin (eq. 2) holds exactly, so a zero row off by delta moves its
    sweep's prime offset by delta times the zero row's leverage h_00, not by delta."""
    # (the prime output is exactly linear in the load here, so the polynomial fits it exactly)
    sensor, calib, fitted = _noise_free_with_bad_zero_rows(delta=1e-3)
    rows = calib.points
    fixed = fitted.points
    for b, axis in enumerate(AXES):
        s = rows["axis"] == axis
        truth = rows.loc[s, f"f{axis}"].to_numpy() * sensor.k[b]  # u_bb = k_bb f_b
        before = rows.loc[s, VOLTAGE_COLUMNS[b]].to_numpy() - truth
        after = fixed.loc[s, VOLTAGE_COLUMNS[b]].to_numpy() - truth
        loaded = rows.loc[s, f"f{axis}"].to_numpy() != 0
        np.testing.assert_allclose(before[loaded], -1e-3, atol=1e-12)  # rows: the bad zero row's bias
        f = rows.loc[s & (rows["repetition"] == 1), f"f{axis}"].to_numpy()
        # every sweep has the same design and the same bad zero row: the joint fit is one
        # polynomial fit of degree d = min(5, levels - 2) (fitted_offsets), whose intercept
        # moves by delta times the zero row's leverage, the hat matrix's diagonal there
        d = min(5, np.unique(f).size - 2)
        x = np.vander(f / np.abs(f).max(), d + 1, increasing=True)
        hat = x @ np.linalg.solve(x.T @ x, x.T)
        h00 = hat[np.flatnonzero(f == 0)[0], np.flatnonzero(f == 0)[0]]
        np.testing.assert_allclose(after[loaded], -1e-3 * h00, rtol=1e-9, atol=1e-15)


def test_cross_offsets_put_chi_through_zero():
    """chi_ab(0) = 0 (eq. 4) fixes each cross-channel level; a zero row off by 1 mV no longer
    sets it alone where loads on both sides of zero pin the smooth chi there."""
    sensor, calib, fitted = _noise_free_with_bad_zero_rows(delta=1e-3)
    fixed = fitted.points
    for b, axis in enumerate(AXES):
        s = (calib.points["axis"] == axis) & (calib.points[f"f{axis}"] != 0)
        f = calib.points.loc[s, f"f{axis}"].to_numpy()
        for a in range(3):
            if a == b:
                continue
            truth = sensor.phi(AXES[a] + axis, f)
            before = np.abs(calib.points.loc[s, VOLTAGE_COLUMNS[a]].to_numpy() - truth).mean()
            after = np.abs(fixed.loc[s, VOLTAGE_COLUMNS[a]].to_numpy() - truth).mean()
            assert before == pytest.approx(1e-3, rel=1e-9)
            if f.min() < 0 < f.max():  # zero inside the sweep: neighbours on both sides
                assert after < 0.6e-3, (AXES[a] + axis, after)
            else:  # zero at the sweep's end: chi(0) is an end value, no better than the zero row
                assert after < 1.2e-3, (AXES[a] + axis, after)


def test_offsets_table_records_the_whole_offset_removed():
    fixed = from_table(_table(SimulatedSensor(), seed=3), FIT)
    p, o = fixed.points, fixed.offsets
    for _, sweep in o.iterrows():
        s = (p["repetition"] == sweep["repetition"]) & (p["axis"] == sweep["axis"])
        for c in VOLTAGE_COLUMNS:
            np.testing.assert_allclose(p.loc[s, f"{c}_raw"] - sweep[c], p.loc[s, c], atol=1e-15)


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_zero_fit_is_recorded_and_rows_keeps_old_bytes(tmp_path, sample_model):
    assert settings_from_dict({"zero": "fit"}).zero == "fit"
    assert "zero" not in Settings().to_dict()
    assert "zero" not in json.loads(sample_model.read_text())["settings"]
    cfg = tmp_path / "c.yaml"
    cfg.write_text("zero: fit\n")
    out = tmp_path / "m.json"
    invoke(["fit", SAMPLE / "calibration", "-c", cfg, "-o", out, "--no-verdict"])
    assert json.loads(out.read_text())["settings"]["zero"] == "fit"
    m = load_model(out)
    assert m.settings.zero == "fit"
    # the fit really used other offsets than the zero rows'
    rows = load_model(sample_model)
    assert not np.array_equal(m.k, rows.k)


@pytest.mark.parametrize("value", ["all", "", 1, None, "ROWS"])
def test_unknown_zero_mode_is_one_line(tmp_path, value):
    with pytest.raises(ConfigError, match=r"zero: expected one of rows, fit"):
        settings_from_dict({"zero": value})
    cfg = tmp_path / "c.yaml"
    cfg.write_text(f"zero: {json.dumps(value)}\n")
    out = tmp_path / "m.json"
    r = invoke(["fit", SAMPLE / "calibration", "-c", cfg, "-o", out], code=2)
    assert "zero: expected one of rows, fit" in r.stderr and not out.exists()


@pytest.mark.slow  # two fits: seconds of CPU; the not-slow run stays under a minute
def test_zero_fit_moves_points_but_not_raw_outputs():
    table = _table(SimulatedSensor(), seed=1)
    rows, fitted = from_table(table, Settings()), from_table(table, FIT)
    for c in VOLTAGE_COLUMNS:
        np.testing.assert_array_equal(rows.points[f"{c}_raw"], fitted.points[f"{c}_raw"])
        assert not np.array_equal(rows.points[c], fitted.points[c])
    a, b = fit(rows, Settings(), tables=False), fit(fitted, FIT, tables=False)
    assert not np.array_equal(a.k, b.k) and np.allclose(a.k, b.k, rtol=1e-3)
