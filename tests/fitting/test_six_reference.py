"""Issue 14: the six-axis pipeline against an independent, straightforward reference.

benchmarks/reference_six.py writes the paper's method out plainly (zero rows,
eq. 2 slopes, one Table-2 libsvm eps-SVR per chi in the data's volts, eq. 11),
sharing nothing with fsdecouple's fitting.  fsdecouple with ``zero: rows`` must
give the same forces: this pins, for N components, the chi training targets, the
kernel width (gamma = 1 / (2 delta^2) in volts, no scaling), the slopes and the
surrogate tables to the paper's method (measured: 1e-10 F.S. apart; gamma = 1 or
``scaling: full_scale`` would be 1e-3 apart).  The default ``zero: fit``
must then be no worse than that reference on a combined-load log.
"""

from __future__ import annotations

import importlib.util
from dataclasses import replace

import numpy as np
import pytest
from conftest import ROOT

from fsdecouple import load_calibration, load_config, load_model
from fsdecouple.config import TABLE2_TOLERANCE
from fsdecouple.data.calibration import from_table
from fsdecouple.fitting.fit import fit
from fsdecouple.fitting.noise import NOISE_FRACTION, SOLVE_FRACTION, noise
from fsdecouple.fitting.threads import single_threaded_libraries


def _reference_module():
    spec = importlib.util.spec_from_file_location("reference_six", ROOT / "benchmarks" / "reference_six.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


REF = _reference_module()
SETTINGS = load_config(ROOT / "configs" / "six-axis.yaml")


@pytest.fixture(scope="module")
def case():
    """(sensor, table, u, f, the reference's forces on u), fitted and decoupled once.

    libsvm is built with OpenMP: its calls run inside single_threaded_libraries, as
    fsdecouple's own do (threads.py).  Unguarded, OpenMP's spin-waiting made this
    fixture and the reference's predictions 30-60x slower (0.5 s -> 30 s) on the
    loaded 2-core test machine.
    """
    sensor, table, u, f = REF.sensor_case(0)
    with single_threaded_libraries():
        ref = REF.Reference(table)
        forces = ref.decouple(u)
    return sensor, table, u, f, ref, forces


@pytest.fixture(scope="module")
def default_model(case):
    """The default (``zero: fit``) model of the case, fitted once for the tests below: without
    the fast path's tables (half its CPU), decoupled on the exact path they stand in for to
    1e-9 F.S. (the zero-rows test holds the tables to the reference)."""
    _, table, *_ = case
    return fit(from_table(table, SETTINGS), SETTINGS, workers=2, tables=False)


OURS_LIMIT, REFERENCE_LIMIT = 3.0, 1.5  # from the scatter over seeds 0-29: see below
FULL_SCALE_LIMIT = 2.35


@pytest.mark.slow  # two six-axis fits: seconds of CPU; the not-slow run stays under a minute
def test_zero_rows_decouples_as_the_straightforward_reference(case):
    sensor, table, u, _, ref, ref_forces = case
    settings = replace(SETTINGS, zero="rows")
    model = fit(from_table(table, settings), settings, workers=2)
    np.testing.assert_allclose(model.k, ref.k, rtol=1e-12)
    # the same libsvm problems in the same point order, on the same machine: the forces
    # differ only by the table path's promise (1e-9 of each full-scale output, decouple.PROMISE)
    diff = np.abs(model.decouple(u, rotate=False) - ref_forces) / np.asarray(sensor.full_scale)
    assert diff.max() < 1e-8, diff.max(axis=0)


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_default_is_no_worse_than_the_reference_on_combined_loads(case, default_model):
    """Every component, and the worst one: a broken zero: fit (or any default that
    drifts from the paper's chi) shows here; measured 1.45-1.92x the floor against the
    reference's 1.6-2.49x on this seed (benchmarks/reference_six.py).

    The limits are from the scatter over seeds 0-29 (this case, sensor_case(seed)),
    worst component of each seed: ours / floor mean 1.92, sd 0.21, max 2.43 (seed 13);
    ours / the reference's mean 0.80, sd 0.15, max 1.23 (seed 10; above 1 on 4 of
    30 seeds: no worse on average, not on every seed).  Limits: the max x 1.25,
    OURS_LIMIT = 3.0x the floor and REFERENCE_LIMIT = 1.5x the reference.
    """
    sensor, _, u, f, _, ref_forces = case
    floor = REF.rms(sensor.solve(u), f)
    ours = REF.rms(default_model.decouple(u, rotate=False), f) / floor
    theirs = REF.rms(ref_forces, f) / floor
    assert ours.max() <= REFERENCE_LIMIT * theirs.max(), (ours, theirs)
    assert (ours <= OURS_LIMIT).all(), ours


@pytest.mark.slow
def test_full_scale_scaling_keeps_six_axis_defaults_near_the_floor(case):
    """What a six-axis config with outputs in mV or counts gets (scaling: full_scale is then
    automatic).  Solved to Table 2's tolerance, 1e-3 F.S. (2-4x the noise), it was 2.3x the
    floor on this seed and 2.6x mean (3.5x worst) over seeds 0-7; solved to half the
    noise (noise.py) it is 1.41x here, and the model records the tolerance used.

    Over seeds 0-29 (worst component of each): mean 1.47, sd 0.14, max 1.87x the floor
    (seed 14); the limit is the max x 1.25, FULL_SCALE_LIMIT = 2.35.  The tolerance the
    model records (1.3e-4 to 2.1e-4 over those seeds) is what tells solving to the noise
    from Table 2's 1e-3.
    """
    sensor, table, u, f, *_ = case
    settings = replace(SETTINGS, scaling="full_scale")
    # no fast-path tables (~0.7 s of the fit's CPU): decoupled on the exact path, which the
    # tables stand in for to 1e-9 F.S.; the accuracy and the tolerance are the point here
    model = fit(from_table(table, settings), settings, workers=1, tables=False)
    ratio = REF.rms(model.decouple(u, rotate=False), f) / REF.rms(sensor.solve(u), f)
    assert (ratio <= FULL_SCALE_LIMIT).all(), ratio
    # the simulator's sigma is 0.5 mV on full-scale outputs of 1-2 V
    assert 1e-4 <= model.settings.svr.tolerance <= 2.5e-4, model.settings.svr.tolerance


@pytest.mark.slow  # six-axis fits: seconds of CPU; the not-slow run stays under a minute
def test_six_axis_volts_keep_the_configured_tolerance_and_three_axes_solve_to_the_noise(
        default_model, sample_model):
    """Six-axis fits in volts keep Table 2's tolerance (fit's 10 s budget); three axes are
    solved to half the noise sigma, at least SOLVE_FRACTION, of the full-scale output in
    any unit (noise.py): a one-repetition load cell in counts (sigma unknown) records
    1e-4, the paper's sensor in volts max(1e-4, sigma / 2) of its smallest |k| F_FS."""
    assert default_model.settings.svr.tolerance == 1e-3
    three = load_config(ROOT / "configs" / "loadcell.yaml")
    assert three.scaling == "full_scale" and three.components is None
    model = fit(load_calibration(ROOT / "sample_data" / "loadcell" / "calibration.csv", three),
                three, workers=1, tables=False)
    assert model.settings.svr.tolerance == pytest.approx(SOLVE_FRACTION, rel=1e-12)
    paper = load_config()
    calib = load_calibration(ROOT / "sample_data" / "calibration", paper)
    model = load_model(sample_model)  # the suite's `fit sample_data/calibration`, no config
    u_fs = np.abs(model.k) * np.asarray(paper.full_scale)
    sigma = noise(calib, paper)
    assert 2e-4 < sigma < 1e-3  # the sample's 0.5 mV on 1-2 V full-scale outputs
    assert model.settings.svr.tolerance == pytest.approx(
        max(SOLVE_FRACTION, NOISE_FRACTION * sigma) * u_fs.min(), rel=1e-9)
    assert paper.svr.tolerance is None and model.settings.svr.tolerance < TABLE2_TOLERANCE
