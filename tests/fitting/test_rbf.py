"""The RBF baselines of Section 4 (rbf.py) and the linear calibration matrix (linear.py)."""

from __future__ import annotations

import numpy as np
import pytest

from fsdecouple.axes import CHI_NAMES
from fsdecouple.fitting.fit import chi_training_data
from fsdecouple.fitting.linear import fit_calibration_matrix
from fsdecouple.fitting.rbf import B_FACTOR, MSE_GOAL, basic_solution, fit_mimo, fit_rbf, fit_siso
from fsdecouple.fitting.threads import single_threaded_libraries


@pytest.fixture(autouse=True)
def _one_blas_thread():
    """The networks trained here as cv trains them (baselines.train_all): BLAS at one
    thread.  Bare, OpenBLAS's spinning threads made these tests 6-12x the CPU in the full
    suite (4.8 s and 3.0 s against 0.4 s and 0.7 s alone)."""
    with single_threaded_libraries():
        yield


def test_b_is_newrbs_0_8326_per_spread():
    assert abs(B_FACTOR - 0.8326) < 1e-4
    net = fit_rbf(np.array([[0.0], [5.0]]), np.array([[1.0], [2.0]]), spread=2.0, goal=0.0)
    # radbas(b * spread) = 0.5: a unit answers half at one spread from its centre
    assert net.design(np.array([[2.0]]))[0, 0] == pytest.approx(0.5, rel=1e-12)


def test_basic_solution_square_and_rank_deficient():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(6, 6))
    t = rng.normal(size=(6, 2))
    x, rank = basic_solution(a, t)
    assert rank == 6 and np.allclose(x, np.linalg.solve(a, t), atol=1e-10)
    # two identical columns: rank 5, one of them gets weight zero (a basic solution,
    # not the minimum-norm one that would split the weight between them)
    b = np.hstack([a[:, :5], a[:, :1]])
    x, rank = basic_solution(b, t)
    assert rank == 5 and (np.abs(x) > 0).all(axis=1).sum() == 5
    lsq = np.linalg.lstsq(b, t, rcond=None)[0]
    assert np.allclose(b @ x, b @ lsq, atol=1e-10)


def test_mimo_interpolates_well_separated_points():
    # 40 points in [-3, 3]^3 with spread 0.3: Phi is well conditioned, so the
    # network passes through every training point up to rounding
    rng = np.random.default_rng(2)
    u = rng.uniform(-3, 3, size=(40, 3))
    f = rng.normal(scale=100.0, size=(40, 3))
    m = fit_mimo(u, f, spread=0.3, goal=0.0)  # goal 0: every point a centre
    assert m.net.rank == 40  # 40 equations, 40 centres + bias: one basic variable stays zero
    assert np.abs(m.decouple(u) - f).max() < 1e-8 * 100.0


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_mimo_on_calibration_data_fits_training_points_and_is_deterministic(calib, settings):
    a = fit_mimo(calib.voltages, calib.forces)
    b = fit_mimo(calib.voltages, calib.forces)
    assert np.array_equal(a.net.weights, b.net.weights) and np.array_equal(a.net.bias, b.net.bias)
    # the zero-load point of every sweep is the same vector (0, 0, 0): one centre
    zero = (calib.voltages == 0).all(axis=1).sum()
    assert zero == 18 and len(a.net.centres) == len(calib.voltages) - zero + 1
    # Spread 1 on volts makes Phi numerically rank deficient (rank well below the
    # number of centres); the basic solution still fits the training forces to
    # noise level, 0.5 mV noise / 13 mV/N ~ 0.04 N, far below 0.5 % F.S.
    assert a.net.rank < len(a.net.centres)
    err = np.abs(a.decouple(calib.voltages) - calib.forces) / np.asarray(settings.full_scale)
    assert err.max() < 0.005


@pytest.mark.slow  # RBF networks trained twice: seconds of CPU; the not-slow run stays under a minute
def test_siso_interpolates_and_is_deterministic(calib):
    x = np.linspace(-1.4, 1.4, 15)
    y = 0.02 * np.sin(3 * x)
    net = fit_rbf(x, y, spread=0.2, goal=0.0)
    assert len(net.centres) == 15
    assert np.abs(net(x.reshape(-1, 1))[:, 0] - y).max() < 1e-10
    data = {name: chi_training_data(calib, name) for name in CHI_NAMES}
    k = np.array([0.0133, 0.0129, 0.0080])
    m1, m2 = fit_siso(k, data), fit_siso(k, data)
    for name in CHI_NAMES:
        a, b = m1.chi[name].net, m2.chi[name].net
        assert np.array_equal(a.weights, b.weights) and np.array_equal(a.centres, b.centres)
        # coupling errors of a few 10 mV are smooth: newrb meets the 2.4e-6 V^2 goal
        # with a few centres and stops (the SISO networks "defined the same as" the MIMO)
        u, e = data[name]
        assert a.train_mse < MSE_GOAL and len(a.centres) < 10
        assert np.mean((m1.chi[name](u) - e) ** 2) == pytest.approx(a.train_mse, rel=1e-9)


def test_newrb_ols_picks_the_best_centre_first_and_stops_at_the_goal():
    x = np.linspace(-2.0, 2.0, 21).reshape(-1, 1)
    bump = np.exp(-((B_FACTOR * (x[:, 0] - 0.6)) ** 2))  # one unit centred on x = 0.6
    net = fit_rbf(x, 3.0 * bump + 0.5)
    # that unit's column matches the target best; with the bias it fits exactly, and
    # newrb checks the goal from the second neuron on, so it stops at two
    assert net.centres[0, 0] == pytest.approx(0.6) and len(net.centres) == 2
    assert net.train_mse < 1e-20
    assert np.allclose(net(x)[:, 0], 3.0 * bump + 0.5, atol=1e-10)


def test_siso_model_decouples_by_eq_11():
    """f_x = (u_x - chi_xy(u_y) - chi_xz(u_z)) / k_xx, and likewise for y and z."""
    k = np.array([0.013, 0.012, 0.008])
    grid = np.linspace(-1.5, 1.5, 13)
    data = {name: (grid, 0.01 * (grid ** 2) * (1 + CHI_NAMES.index(name))) for name in CHI_NAMES}
    m = fit_siso(k, data, spread=0.3)
    u = np.random.default_rng(3).uniform(-1.2, 1.2, size=(20, 3))
    ux, uy, uz = u.T
    c = m.chi
    expected = np.column_stack([
        (ux - c["xy"](uy) - c["xz"](uz)) / k[0],
        (uy - c["yx"](ux) - c["yz"](uz)) / k[1],
        (uz - c["zx"](ux) - c["zy"](uy)) / k[2],
    ])
    assert np.allclose(m.decouple(u), expected, rtol=1e-13, atol=1e-12)


def test_linear_method_recovers_an_exactly_linear_coupled_sensor():
    k = np.array([[0.0133, 0.0004, -0.0006],
                  [-0.0003, 0.0129, 0.0005],
                  [0.0007, -0.0002, 0.0080]])  # u = K f, non-diagonal
    loads = np.linspace(-100, 100, 21)
    f = np.vstack([np.outer(loads, e) for e in np.eye(3)])
    u = f @ k.T
    cal = fit_calibration_matrix(u, f)
    assert np.allclose(cal.C, np.linalg.inv(k), rtol=1e-10, atol=1e-9)
    assert np.allclose(cal.decouple(u), f, atol=1e-9)
