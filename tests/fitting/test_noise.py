"""libsvm's stopping tolerance against full scale (fitting/noise.py, issue 24).

Table 2's tolerance (1e-3) is ten times its epsilon (1e-4): solved to it, a chi
missed its own calibration points by up to ~1e-3 of full scale and a load cell's
tare row decoupled to -1.06 gf of 1000.  Solved to 1e-4 of the full-scale output in
any unit, a chi meets its points within about epsilon + tolerance, and the same
calibration in V, mV and counts gives the same residuals relative to full scale.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
from conftest import ROOT

from fsdecouple import load_calibration, load_config
from fsdecouple.data.calibration import from_table
from fsdecouple.fitting.fit import chi_training_data, fit
from fsdecouple.fitting.noise import SOLVE_FRACTION
from fsdecouple.sim.simulate import SimulatedSensor, simulate_calibration
from fsdecouple.units import Units

EPSILON = 1e-4  # Table 2's epsilon, as a fraction of full scale in normalised units
# a converged epsilon-SVR meets a point within epsilon; the solver's stopping
# tolerance adds up to itself: 2e-4, and 25 % for libsvm's KKT measure
THROUGH = 1.25 * (EPSILON + SOLVE_FRACTION)


def _residuals(model, calib) -> dict[str, float]:
    """Largest |chi(u) - e| at the chi's own training points, / its output's F.S. output."""
    u_fs = np.abs(model.k) * np.asarray(model.settings.full_scale)
    out = {}
    for name, chi in model.chi.items():
        x, y = chi_training_data(calib, name)
        out[name] = float(np.abs(chi(x) - y).max() / u_fs[chi.output_axis])
    return out


def test_load_cell_in_counts_passes_through_its_points_and_tares_to_zero():
    """sample_data/loadcell (one repetition, ADC counts, gram-force): every chi within
    THROUGH of its points (Table 2's 1e-3 tolerance left 8.5e-4 F.S.), and the tare
    row (zero outputs after zero correction) decouples within two epsilon-tubes:
    -(chi_ab(0) + chi_ac(0)) / k_a (it was -1.06 gf of 1000)."""
    settings = load_config(ROOT / "configs" / "loadcell.yaml")
    calib = load_calibration(ROOT / "sample_data" / "loadcell" / "calibration.csv", settings)
    model = fit(calib, settings, workers=1)
    worst = _residuals(model, calib)
    assert max(worst.values()) <= THROUGH, worst
    tare = model.decouple(np.zeros((1, 3)), rotate=False)[0] / np.asarray(settings.full_scale)
    assert np.abs(tare).max() <= 2 * THROUGH, tare


def _in_unit(table: pd.DataFrame, factor: float, integer: bool) -> pd.DataFrame:
    out = table.copy()
    for c in ("ux", "uy", "uz"):
        out[c] = np.round(out[c] * factor) if integer else out[c] * factor
    return out


def test_the_same_calibration_in_volts_millivolts_and_counts_gives_the_same_residuals():
    """A quiet simulated sensor (noise 1 uV, so epsilon and the solver decide the
    residuals), one repetition, written in V, mV and 24-bit counts of 2.5 V: every chi
    within THROUGH of its points in each unit, and the three agree within epsilon.
    With Table 2's tolerance the volts fit left 3e-4-1e-3 F.S. (the units disagreed)."""
    sensor = replace(SimulatedSensor(), noise=1e-6)
    table = simulate_calibration(sensor, repetitions=1, seed=3)
    base = replace(load_config(), min_repetitions=1)
    figures = {}
    for unit, factor, integer in (("V", 1.0, False), ("mV", 1e3, False),
                                  ("count", 2**24 / 2.5, True)):
        settings = base if unit == "V" else replace(
            base, scaling="full_scale", units=Units(load="N", output=unit))
        calib = from_table(_in_unit(table, factor, integer), settings)
        model = fit(calib, settings, workers=1, tables=False)
        figures[unit] = _residuals(model, calib)
        assert max(figures[unit].values()) <= THROUGH, (unit, figures[unit])
    for name in figures["V"]:
        spread = [figures[u][name] for u in figures]
        assert max(spread) - min(spread) <= EPSILON, (name, figures)
