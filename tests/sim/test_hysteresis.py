"""simulate --hysteresis: sweeps out and back, and a lag largest mid-range (issue 24)."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from conftest import FAST_CONFIG, invoke

from fsdecouple import load_config
from fsdecouple.data.calibration import load_calibration
from fsdecouple.sim.hysteresis import WIDTH, lagged, up_and_down
from fsdecouple.sim.simulate import (
    PAPER_GRIDS,
    SimulatedSensor,
    simulate_calibration,
    simulate_task,
    with_coupling,
)


def _loop(fraction: float) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free prime output of x swept -100 .. 100 .. -100 N, as a fraction of full scale."""
    sensor = replace(SimulatedSensor(), hysteresis=fraction)
    loads = up_and_down(PAPER_GRIDS[0])
    f = np.zeros((loads.size, 3))
    f[:, 0] = loads
    lag = (sensor.outputs(f) - sensor.voltages(f))[:, 0] / sensor.full_scale_output[0]
    return loads, lag


def test_the_way_down_reads_above_the_way_up_most_mid_range():
    fraction = 0.002
    loads, lag = _loop(fraction)
    n = PAPER_GRIDS[0].size
    up, down = lag[:n], lag[n - 1:][::-1]  # both on the grid -100 .. 100
    assert (loads[:n] == loads[n - 1:][::-1]).all()
    gap = down - up
    # by hand: r = fraction / 2, lambda = WIDTH F_FS; the approach 0 -> -F_FS leaves
    # z0 = r (1 - e^(-1/WIDTH)); up from -F_FS: z = -r + (z0 + r) e^(-(f + F) / lambda);
    # at zero load on the way down (from +F_FS, where z = z_top): z = r + (z_top - r) e^(-F/lambda)
    r, e = fraction / 2, math.exp(-1 / WIDTH)
    z0 = r * (1 - e)
    z_up0 = -r + (z0 + r) * e
    z_top = -r + (z0 + r) * e * e
    z_down0 = r + (z_top - r) * e
    mid = n // 2
    assert PAPER_GRIDS[0][mid] == 0.0
    assert gap[mid] == pytest.approx(z_down0 - z_up0, rel=1e-9)
    assert 0.9 * fraction < gap[mid] <= fraction  # "largest mid-range", close to the fraction
    assert np.argmax(gap) == mid and abs(gap[-1]) < 0.05 * fraction  # meet where they turn
    assert (gap[1:-1] > 0).all()


def test_lag_follows_any_path_and_vanishes_without_hysteresis():
    f = np.column_stack([np.linspace(0, 50, 11), np.zeros(11), np.zeros(11)])
    assert (lagged(f, (100.0, 100.0, 150.0), 0.0) == f).all()
    out = lagged(f, (100.0, 100.0, 150.0), 0.01)
    assert (out[:, 1:] == 0).all()  # components that do not move do not lag
    assert (out[1:, 0] < f[1:, 0]).all()  # rising: the body lags below the load
    assert (f[:, 0] - out[:, 0]).max() <= 0.5 * 0.01 * 100.0  # never beyond r


@pytest.mark.slow  # a fit: ~1-3 s
def test_calibration_sweeps_out_and_back_and_fits(tmp_path):
    invoke(["simulate", tmp_path / "h", "--hysteresis", "0.001", "--coupling", "0.05",
            "--seed", "3"])
    rep = pd.read_csv(tmp_path / "h" / "calibration" / "rep1.csv")
    x = rep[rep["axis"] == "x"]["fx"].to_numpy()
    assert (x == up_and_down(PAPER_GRIDS[0])).all()
    z = rep[rep["axis"] == "z"]["fz"].to_numpy()
    assert z[0] == z[-1] == 0.0 and z.min() == -150.0  # two zero rows: before and after
    calib = load_calibration(tmp_path / "h" / "calibration", load_config())
    assert len(calib.points) == 6 * len(rep)
    # Table 2's tolerance, no verdict: how the sweeps are zeroed is the point, not the chi
    r = invoke(["fit", tmp_path / "h" / "calibration", "-o", tmp_path / "m.json",
                "-c", FAST_CONFIG, "--no-verdict"])
    # out-and-back sweeps are zeroed from all points, and the model file says so
    assert "out and back" in r.stderr
    assert json.loads((tmp_path / "m.json").read_text())["settings"]["zero"] == "fit"
    # the task log lags too: against the same sensor and seed without the lag, by about
    # r = fraction / 2 of full-scale output; each output also moves with the other loads'
    # lags through its coupling functions (slopes up to ~0.2 at 5 % coupling)
    sensor = with_coupling(SimulatedSensor(), 0.05)
    lag = replace(sensor, hysteresis=0.001)
    u = pd.read_csv(tmp_path / "h" / "task_voltages.csv")[["ux", "uy", "uz"]].to_numpy()
    static = simulate_task(sensor, seed=3)[0][["ux", "uy", "uz"]].to_numpy()
    d = np.abs(u - static) / lag.full_scale_output
    assert 0.3 * 0.0005 < d.max() < 0.0005 * 1.5


def test_without_the_option_the_sets_are_unchanged():
    # hysteresis None: one-way sweeps and no lag, the same numbers as before the option
    a = simulate_calibration(SimulatedSensor(), seed=4)
    b = simulate_calibration(replace(SimulatedSensor(), hysteresis=None), seed=4)
    pd.testing.assert_frame_equal(a, b)
    assert len(a) == 6 * sum(g.size for g in PAPER_GRIDS)
    # hysteresis 0: out and back, no lag: the way back reads what the way out did, less noise
    c = simulate_calibration(replace(SimulatedSensor(noise=0.0), hysteresis=0.0), seed=4)
    x = c[(c["axis"] == "x") & (c["repetition"] == 1)]["ux"].to_numpy()
    n = PAPER_GRIDS[0].size
    assert x[:n] == pytest.approx(x[n - 1:][::-1], abs=1e-12)


@pytest.mark.parametrize("args, message", [
    (["--hysteresis", "0.5"], "--hysteresis 0.5: expected"),
    (["--hysteresis", "-0.001"], "--hysteresis -0.001: expected"),
    (["--hysteresis", "0.001", "--layout", "lab"], "only with --layout paper"),
    (["--hysteresis", "0.001", "--components", "6"], "three-axis paper layout"),
])
def test_bad_hysteresis_is_one_line_exit_2_nothing_written(tmp_path, args, message):
    r = invoke(["simulate", tmp_path / "out", *args], code=2)
    err = r.stderr.strip()
    assert message in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "out").exists()
