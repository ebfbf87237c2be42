"""``zero: fit``: each sweep's offsets from all its points (fsdecouple/zero_fit.py)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from conftest import SAMPLE, invoke

from fsdecouple import load_model
from fsdecouple.axes import AXES, VOLTAGE_COLUMNS
from fsdecouple.calibration import from_table
from fsdecouple.config import Settings, settings_from_dict
from fsdecouple.errors import ConfigError
from fsdecouple.fit import fit
from fsdecouple.simulate import SimulatedSensor, simulate_calibration
from fsdecouple.zero_fit import fit_offsets


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
    return sensor, from_table(table, Settings())


def test_prime_offsets_come_from_every_point():
    """omega through the origin (eq. 2) holds exactly, so a zero row off by delta moves its
    sweep's prime offset by delta times the zero row's leverage h_00, not by delta."""
    sensor, calib = _noise_free_with_bad_zero_rows(delta=1e-3)
    rows = calib.points
    fixed = fit_offsets(calib).points
    for b, axis in enumerate(AXES):
        s = rows["axis"] == axis
        truth = rows.loc[s, f"f{axis}"].to_numpy() * sensor.k[b]  # u_bb = k_bb f_b
        before = rows.loc[s, VOLTAGE_COLUMNS[b]].to_numpy() - truth
        after = fixed.loc[s, VOLTAGE_COLUMNS[b]].to_numpy() - truth
        loaded = rows.loc[s, f"f{axis}"].to_numpy() != 0
        np.testing.assert_allclose(before[loaded], -1e-3, atol=1e-12)  # rows: the bad zero row's bias
        f = rows.loc[s & (rows["repetition"] == 1), f"f{axis}"].to_numpy()
        # every sweep has the same design and the same bad zero row: the common-slope fit is
        # one straight-line fit, whose intercept moves by delta * (1/n + mean(f)^2 / Sxx)
        h00 = 1.0 / f.size + f.mean() ** 2 / ((f - f.mean()) ** 2).sum()
        np.testing.assert_allclose(after[loaded], -1e-3 * h00, rtol=1e-9, atol=1e-15)


def test_cross_offsets_put_chi_through_zero():
    """chi_ab(0) = 0 (eq. 4) fixes each cross-channel level; a zero row off by 1 mV no longer
    sets it alone where loads on both sides of zero pin the smooth chi there."""
    sensor, calib = _noise_free_with_bad_zero_rows(delta=1e-3)
    fixed = fit_offsets(calib).points
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
    calib = from_table(_table(SimulatedSensor(), seed=3), Settings())
    fixed = fit_offsets(calib)
    p, o = fixed.points, fixed.offsets
    for _, sweep in o.iterrows():
        s = (p["repetition"] == sweep["repetition"]) & (p["axis"] == sweep["axis"])
        for c in VOLTAGE_COLUMNS:
            np.testing.assert_allclose(p.loc[s, f"{c}_raw"] - sweep[c], p.loc[s, c], atol=1e-15)


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


def test_zero_fit_runs_inside_cross_validation_folds():
    """cv fits on training repetitions only: the offsets are found per fold, from that fold."""
    calib = from_table(_table(SimulatedSensor(), seed=1), Settings())
    s = replace(Settings(), zero="fit")
    whole = fit(calib, s, tables=False)
    part = fit(calib.subset([1, 2, 3]), s, tables=False)
    assert not np.array_equal(whole.k, part.k)
    assert np.allclose(whole.k, part.k, rtol=1e-3)
