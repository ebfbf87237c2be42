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
certificate.md): at P = 0.95 the largest width ratio was 0.51, the median coverage per
scenario 0.952-0.973, and every component of all 44 zero-row sensors (the paper's and
the coupled ones: the least-squares sweep model's centre and variance) lay in
0.92-0.985, so the four here are held to that window per sensor (measured 0.950-0.981;
the earlier construction put seed 0's fy at 0.905).  The sensors swept out and back keep
the earlier construction, whose coverage scatters from sensor to sensor (11 of the 14
pass): they are held to their scenario's median, with the fraction of all components
in the window above the earlier method's 28 of 36 (0.78; here 17 of 18).  At P = 0.9
the median over the six is 0.930, held to 0.87-0.94.  The sensors are fixed: the
figures move only with the method.
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
        assert (w <= 0.75).all(), (label, w)  # largest measured 0.51 (58 sensors)


def test_the_coverage_at_095_holds_on_each_zero_row_sensor(measured):
    coverage, _ = measured
    for label in ("paper", "coupling 5 %"):
        c = coverage[label][0.95]
        assert ((c >= 0.92) & (c <= 0.985)).all(), (label, c)


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



def test_a_six_axis_sensor_with_zero_rows_is_covered_on_every_component(tmp_path):
    """The sweep model in six dimensions: ``simulate --components 6 --seed 3`` fitted with
    ``zero: rows`` covers 0.939-0.975 of its task log's true loads per component (the
    earlier construction: 0.865-0.962, four components below 0.92)."""
    from fsdecouple import decouple_frame
    from fsdecouple.sim.six_axis import write_six_axis

    write_six_axis(tmp_path, seed=3)
    config = tmp_path / "rows.yaml"
    config.write_text((tmp_path / "sensor.yaml").read_text() + "\nzero: rows\n")
    settings = load_config(config)
    model = calibrate(load_calibration(tmp_path / "calibration", settings), settings)
    assert "least_squares" in model.report.certificate["interval"]
    got = decouple_frame(model, pd.read_csv(tmp_path / "task_voltages.csv"), tare=TARE, interval=0.95)
    truth = pd.read_csv(tmp_path / "task_forces.csv").drop(columns="t")
    for c in truth.columns:
        covered = ((truth[c] >= got[f"{c}_lo"]) & (truth[c] <= got[f"{c}_hi"])).mean()
        assert 0.92 <= covered <= 0.985, (c, covered)


def test_sweeps_out_and_back_keep_the_earlier_construction_even_with_zero_rows(tmp_path):
    """The lag of sweeps out and back is not in the sweep model (7 of 14 simulated
    sensors passed with it, 11 without): a config that asks for ``zero: rows`` on such
    sweeps gets the held-out construction, not the sweep model."""
    simulate(tmp_path, seed=200, hysteresis=0.001)
    config = tmp_path / "rows.yaml"
    config.write_text("zero: rows\n")
    settings = load_config(config)
    model = calibrate(load_calibration(tmp_path / "calibration", settings), settings)
    interval = model.report.certificate["interval"]
    assert "least_squares" not in interval and "deviations" in interval
