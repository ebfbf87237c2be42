"""apply --interval's coverage and width, per sensor, on simulated sensors (issue 33).

Twelve sensors: the paper's (seeds 0-3), one whose coupling peaks at 5 % F.S. (the
intervals were twice the width bound there, covering every row: seeds 100-103) and one
with a 0.1 % F.S. lag (they covered 0.87-0.93: seeds 200-203).  Each is simulated,
fitted as ``fit`` does, and its combined-load task log decoupled with a tare of 200
rows; a component's coverage is the fraction of rows whose true force lies in
[lo, hi], its width ratio the mean width over 5 x 1.96 x the RMS error of decoupling
with the simulator's true coupling functions (the floor).

The limits come from ``benchmarks/interval_coverage.py`` over 58 sensors (docs/
certificate.md): at P = 0.95 the largest width ratio was 0.53, the median coverage per
scenario 0.949-0.965.  In these twelve sensors (in memory, the same fits) 32 of the 36
component coverages lay in 0.92-0.985 (0.89), none above, the median at P = 0.9 was
0.909 (the shared part a bias per sensor at its 90 % bound: 31 of 36 with it averaged
over sensors; before the within-sweep deviations, the zero readings' share and the
centre's zero shift, 28 of 36, four of them above 0.985).  One log's coverage scatters
from sensor to sensor (what the model inherits from the zero readings is one
realisation, the same on every row), so single sensors are not held to the window; the
fraction in it is, above the earlier method's 28 of 36 (2.1 binomial standard
deviations below the measured 0.89; the twelve sensors are fixed, so the figure moves
only with the method).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from fsdecouple import load_calibration, load_config
from fsdecouple.evaluation.calibrate import fit as calibrate
from fsdecouple.evaluation.intervals import with_intervals
from fsdecouple.sim.simulate import SimulatedSensor, simulate, with_coupling

pytestmark = pytest.mark.slow
SCENARIOS = {  # label: (coupling, hysteresis, seeds)
    "paper": (None, None, range(0, 4)),
    "coupling 5 %": (0.05, None, range(100, 104)),
    "hysteresis 0.1 %": (None, 0.001, range(200, 204)),
}
TARE = 200


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    """label -> {P: coverage (sensors, 3)}, and label -> width ratio at 0.95 (sensors, 3)."""
    settings = load_config()
    coverage, width = {}, {}
    for label, (coupling, hysteresis, seeds) in SCENARIOS.items():
        truth_sensor = SimulatedSensor() if coupling is None else with_coupling(SimulatedSensor(), coupling)
        truth_sensor = replace(truth_sensor, hysteresis=hysteresis)
        coverage[label], width[label] = {0.9: [], 0.95: []}, []
        for seed in seeds:
            d = tmp_path_factory.mktemp(f"cov{seed}")
            simulate(d, seed=seed, coupling=coupling, hysteresis=hysteresis)
            model = calibrate(load_calibration(d / "calibration", settings), settings)
            u = pd.read_csv(d / "task_voltages.csv")[["ux", "uy", "uz"]].to_numpy()
            truth = pd.read_csv(d / "task_forces.csv")[["fx", "fy", "fz"]].to_numpy()
            u = u - u[:TARE].mean(axis=0)
            f = model.decouple(u, rotate=False)
            floor = np.sqrt(np.mean((truth_sensor.solve(u) - truth) ** 2, axis=0))
            for p in (0.9, 0.95):
                w = with_intervals(model, f, p, u)
                lo, hi = w[:, 3::2], w[:, 4::2]
                coverage[label][p].append(((truth >= lo) & (truth <= hi)).mean(axis=0))
                if p == 0.95:
                    width[label].append((hi - lo).mean(axis=0) / (5 * 1.96 * floor))
    return ({k: {p: np.array(v) for p, v in c.items()} for k, c in coverage.items()},
            {k: np.array(v) for k, v in width.items()})


def test_every_sensor_keeps_the_width_bound(measured):
    _, width = measured
    for label, w in width.items():
        assert (w <= 0.75).all(), (label, w)  # largest measured 0.52


def test_the_coverage_at_095_holds_per_scenario_and_mostly_per_sensor(measured):
    coverage, _ = measured
    everything = np.concatenate([c[0.95].ravel() for c in coverage.values()])
    inside = ((everything >= 0.92) & (everything <= 0.985)).mean()
    assert inside > 0.78, everything
    for label, c in coverage.items():
        assert 0.93 <= np.median(c[0.95]) <= 0.985, (label, c[0.95])


def test_the_coverage_at_09_is_centred_on_it(measured):
    coverage, _ = measured
    everything = np.concatenate([c[0.9].ravel() for c in coverage.values()])
    assert 0.87 <= np.median(everything) <= 0.94, everything
