"""Sweeps out and back are zeroed from all their points unless the config says rows (issue 24)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
from conftest import SAMPLE

from fsdecouple import load_config
from fsdecouple.data.calibration import from_table, load_calibration
from fsdecouple.data.zero import out_and_back
from fsdecouple.sim.simulate import SimulatedSensor, simulate_calibration


def _table(hysteresis, noise=None):
    sensor = replace(SimulatedSensor(), hysteresis=hysteresis)
    if noise is not None:
        sensor = replace(sensor, noise=noise)
    return simulate_calibration(sensor, seed=2)


def test_out_and_back_is_a_load_visited_twice_in_one_sweep():
    assert out_and_back(_table(0.001))
    assert out_and_back(_table(0.0))  # the sweep's shape, not its lag
    assert not out_and_back(_table(None))
    one_way = _table(None)
    # the same load in two repetitions is no loop
    assert one_way.duplicated(["axis", "fx", "fy", "fz"]).any() and not out_and_back(one_way)
    # a sweep pasted twice turns twice (-100 .. 100, -100 .. 100): a slip, not a loop
    pasted = pd.concat([one_way, one_way]).sort_values(["repetition", "axis"], kind="stable")
    assert not out_and_back(pasted)
    assert out_and_back(pd.concat([one_way, one_way.iloc[::-1]]).sort_values(
        ["repetition", "axis"], kind="stable"))  # there and back again: a loop


def test_out_and_back_sets_are_zeroed_by_fitted_offsets_unless_the_config_says_rows():
    settings = load_config()
    assert settings.zero is None and settings.zero_method == "rows"
    calib = from_table(_table(0.001), settings)
    assert calib.zero == "fit" and any("out and back" in w for w in calib.warnings)
    rows = from_table(_table(0.001), replace(settings, zero="rows"))
    assert rows.zero == "rows" and not any("out and back" in w for w in rows.warnings)
    sample = load_calibration(SAMPLE / "calibration", settings)
    assert sample.zero == "rows" and not any("out and back" in w for w in sample.warnings)


def test_the_offsets_are_those_of_zero_fit():
    table = _table(0.001)
    settings = load_config()
    auto = from_table(table, settings)
    fitted = from_table(table, replace(settings, zero="fit"))
    rows = from_table(table, replace(settings, zero="rows"))
    outputs = ["ux", "uy", "uz"]
    np.testing.assert_array_equal(auto.offsets[outputs], fitted.offsets[outputs])
    assert not np.allclose(auto.offsets[outputs], rows.offsets[outputs], rtol=0, atol=1e-6)
    # and the fitted offsets are the shared-polynomial fit's, not the zero rows' mean
    assert (auto.offsets["n_zero"] == 2).all()
