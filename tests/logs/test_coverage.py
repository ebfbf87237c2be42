"""apply --interval's coverage and width, per sensor, on simulated sensors (issue 33).

Six sensors, two per scenario: the paper's (seeds 0 and 7; seed 7 is the session's
``fit`` of ``simulate --seed 7``, ``sim_fit``), one whose coupling peaks at 5 % F.S. (the
intervals were twice the width bound there, covering every row: seeds 100-101) and one
with a 0.1 % F.S. lag (they covered 0.87-0.93: seeds 200-201).  Each is simulated,
fitted as ``fit`` does, and its combined-load task log decoupled with a tare of 200 rows;
a component's coverage is the fraction of rows whose true force lies in [lo, hi], its
width ratio the mean width over 5 x 1.96 x the RMS error of decoupling with the
simulator's true coupling functions (the floor).

The limits come from ``benchmarks/interval_coverage.py`` over 58 sensors (docs/
certificate.md): at P = 0.95 the largest width ratio was 0.54, the median coverage per
scenario 0.952-0.973.  One log's coverage scatters from sensor to sensor (what the model
inherits from the zero readings is one realisation, the same on every row), so single
sensors are not held to the window; the fraction of components in it is, above the
earlier method's 28 of 36 (0.78; before the within-sweep deviations, the zero readings'
share and the centre's zero shift, four of those 36 were above 0.985).

Two sensors per scenario, not four (half the CPU: a fit with its verdict each): the
benchmark's 36 sensors of these scenarios (seeds 0-19, 100-107, 200-207, this version,
in memory as below) put 103 of their 108 component coverages in the window (0.95).
Over all 148,960 choices of two sensors per scenario among them the fraction in the
window was 0.78-1.0 (1 % quantile 0.83: 15 of 18, the least above 0.78), the smallest
scenario median at 0.95 0.9375, the largest 0.976, and the median at 0.9 0.888-0.946
(1 % / 99 % quantiles 0.896 / 0.938); every width ratio at most 0.54.  So the limits
stand as they were for twelve sensors: the fraction above 0.78 (these six: 16 of 18,
0.889; the twelve of seeds 0-3, 100-103, 200-203: 33 of 36), each scenario's median in
0.93-0.985 (0.942-0.963), the median at 0.9 in 0.87-0.94 (0.902), width at most 0.75.
The sensors are fixed: the figures move only with the method.
"""

from __future__ import annotations

import functools
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from fsdecouple import load_calibration, load_config, load_model
from fsdecouple.evaluation.calibrate import fit as calibrate
from fsdecouple.evaluation.intervals import with_intervals
from fsdecouple.sim.simulate import SimulatedSensor, simulate, with_coupling

pytestmark = pytest.mark.slow
SCENARIOS = {  # label: (coupling, hysteresis, seeds)
    "paper": (None, None, (0, 7)),
    "coupling 5 %": (0.05, None, range(100, 102)),
    "hysteresis 0.1 %": (None, 0.001, range(200, 202)),
}
TARE = 200


@pytest.fixture(scope="module")
def measured(tmp_path_factory, sim_dir, sim_model_file):
    """label -> {P: coverage (sensors, 3)}, and label -> width ratio at 0.95 (sensors, 3)."""
    import fsdecouple.fitting.fit as fitting

    settings = load_config()
    coverage, width = {}, {}
    # each model without the fast path's tables (~0.1-0.6 s of a fit's CPU): decoupled on
    # the exact path, which the tables stand in for to 1e-9 F.S.; model, verdict and
    # intervals are fit's
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(fitting, "fit", functools.partial(fitting.fit, tables=False))
        for label, (coupling, hysteresis, seeds) in SCENARIOS.items():
            truth_sensor = (SimulatedSensor() if coupling is None
                            else with_coupling(SimulatedSensor(), coupling))
            truth_sensor = replace(truth_sensor, hysteresis=hysteresis)
            coverage[label], width[label] = {0.9: [], 0.95: []}, []
            for seed in seeds:
                if (coupling, hysteresis, seed) == (None, None, 7):  # fitted once a session
                    d, model = sim_dir, load_model(sim_model_file)
                else:
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
        assert (w <= 0.75).all(), (label, w)  # largest measured 0.54 (58 sensors)


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
