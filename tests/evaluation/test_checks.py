"""Assumption checks of Section 2.1 and the eq. (6) bound.

Every figure a check reports is derived here another way: the slopes by a finite
difference of the model's chi (not ``chi_slope``), the bounds from the simulator's
true coupling functions, and the limits from a hand-built model whose chi have
analytic peaks and slopes.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from fsdecouple.config import Settings
from fsdecouple.core.model import Chi, CouplingErrorModel
from fsdecouple.evaluation.checks import SECOND_ORDER_LIMIT, assumption_checks, chi_slope

AXES = "xyz"


def by_key(model) -> dict[tuple[str, str], object]:
    return {(c.name, c.subject): c for c in assumption_checks(model)}


def central_difference(f, u: np.ndarray, h: float = 1e-4) -> np.ndarray:
    # h balances roundoff (the dual coefficients, up to C = 1000, cancel:
    # ~1e-16 * sum|c| / h) against truncation (h^2 * third derivative / 6)
    return (f(u + h) - f(u - h)) / (2 * h)


def true_chi(sensor, name: str):
    """The simulator's corrected coupling function chi_ab(u_bb) = phi_ab(u_bb / k_bb) (eq. 4)."""
    b = AXES.index(name[1])
    return lambda u: sensor.phi(name, np.asarray(u) / sensor.k[b])


def test_slope_matches_finite_difference(model):
    for c in model.chi.values():
        lo, hi = c.input_range
        u = np.linspace(lo, hi, 101)
        # the kernel sum's: at the range's ends a tangent-extrapolating chi has a kink in chi''
        np.testing.assert_allclose(chi_slope(c, u), central_difference(c.kernel, u), rtol=0, atol=1e-6)


def test_checks_on_simulated_sensor(model, sensor):
    checks = by_key(model)
    assert len(checks) == 3 + 3 + 6 + 6
    # the simulated coupling is 1.1-2.7 % F.S. per pair, so per channel it is the
    # sum of two pair amplitudes; the fitted chi carry the 0.5 mV noise (about
    # 0.04 % of a 1.2-1.3 V full-scale output) and the epsilon tube, so they find
    # each peak within 0.1 % F.S. (seed 7: 0.08 % at worst)
    for a, axis in enumerate(AXES):
        truth = sum(sensor.amplitude[a])
        assert abs(checks[("coupling", axis)].value - truth) < 0.001
        assert checks[("coupling", axis)].status == "pass"
    assert all(checks[("linearity", a)].status == "pass" for a in AXES)


def test_second_order_bound_rederived_from_the_models_chi(model):
    """Eq. (6) from the model's chi values alone: slope by central difference on a
    10x denser grid than the check's, coupling as the summed peaks of the chi into
    the input channel over their calibrated range, full scale |k| F_FS."""
    checks = by_key(model)
    u_fs = np.abs(model.k) * np.asarray(model.settings.full_scale)
    peak, slope = {}, {}
    for name, c in model.chi.items():
        u = np.linspace(*c.input_range, 20_001)
        peak[name] = np.abs(c(u)).max()
        slope[name] = np.abs(central_difference(c, u)).max()
    coupling = {axis: sum(v for n, v in peak.items() if n[0] == axis) / u_fs[a]
                for a, axis in enumerate(AXES)}
    # the check's 2001-point grid finds each maximum of these smooth curves within
    # about (grid step)^2 * curvature: well below 1e-4 relative
    for axis in AXES:
        assert checks[("coupling", axis)].value == pytest.approx(coupling[axis], rel=1e-4)
    for name in model.chi:
        assert checks[("slope", name)].value == pytest.approx(slope[name], rel=1e-4)
        bound = slope[name] * coupling[name[1]]
        assert checks[("second_order", name)].value == pytest.approx(bound, rel=2e-4)
        assert checks[("second_order", name)].status == ("pass" if bound <= SECOND_ORDER_LIMIT
                                                         else "warn")


def test_second_order_bound_matches_the_simulated_truth(model, sensor):
    """The check's bound against the one the simulator's true chi give: true max slope
    (finite difference of phi(u / k)) times the true coupling fraction (the summed
    amplitudes).  The fit sees 0.5 mV noise, ten times its epsilon-tube, and libsvm
    solved to 1e-4 F.S. (noise.py; now sigma / 2, looser) follows it: the largest slope of a chi is up to
    37 % off the true one (worst chi of 20 seeds 0-19: mean 16 %, seed 18 37 %,
    seed 7 24 %); the coupling moves < 3 %.  50 % covers both with margin."""
    checks = by_key(model)
    for name in model.chi:
        b = AXES.index(name[1])
        lo, hi = model.chi[name].input_range
        u = np.linspace(lo, hi, 20_001)
        true_slope = np.abs(central_difference(true_chi(sensor, name), u)).max()
        true_bound = true_slope * sum(sensor.amplitude[b])
        assert checks[("second_order", name)].value == pytest.approx(true_bound, rel=0.50), name


def test_true_second_order_error_obeys_the_checks_bound(model, sensor, sim_dir):
    """Eq. (5) with the simulator's truth on combined loads: |chi_ab(u_b) - chi_ab(u_bb)| /
    u_b(FS), with the true chi, noise-free task voltages u_b and true prime voltages
    u_bb = k_b f_b, never exceeds what the check reports (no slack: seed 7 reaches
    74 % of the bound on chi_yz)."""
    checks = by_key(model)
    f = pd.read_csv(sim_dir / "task_forces.csv")[["fx", "fy", "fz"]].to_numpy()
    u_t = sensor.voltages(f)
    u_prime = f * sensor.k
    u_fs = sensor.full_scale_output
    worst = {}
    for name in model.chi:
        b = AXES.index(name[1])
        chi = true_chi(sensor, name)
        worst[name] = (np.abs(chi(u_t[:, b]) - chi(u_prime[:, b])) / u_fs[b]).max()
        assert worst[name] <= checks[("second_order", name)].value, name
    # the combined loads do exercise the bound: not a vacuous comparison with zero
    assert max(worst[n] / checks[("second_order", n)].value for n in worst) > 0.5


def test_second_order_bound_holds_on_task_data(model, sim_dir, sensor):
    """The same with the model's own chi: |chi(u_t) - chi(u_bb)| / u_FS obeys the bound."""
    f = pd.read_csv(sim_dir / "task_forces.csv")[["fx", "fy", "fz"]].to_numpy()
    u_t = sensor.voltages(f)  # noise-free task voltages
    u_prime = f * sensor.k  # the prime voltages u_bb
    u_fs = np.abs(model.k) * np.array([100.0, 100.0, 150.0])
    checks = {(c.name, c.subject): c.value for c in assumption_checks(model)}
    for name, c in model.chi.items():
        b = AXES.index(name[1])
        err = np.abs(c(u_t[:, b]) - c(u_prime[:, b])) / u_fs[b]
        assert err.max() <= checks[("second_order", name)]


def bump_model(coupling: float, slope: float) -> CouplingErrorModel:
    """A model whose six chi are single Gaussian bumps A exp(-g u^2) on [-1.5, 1.5] V.

    Analytically max|chi| = A (at u = 0) and max|chi'| = A sqrt(2 g / e) (at
    u = +-1/sqrt(2g)).  A = coupling/2 * u_FS of the output channel (two chi per
    channel) and g chosen for the slope give a sensor exactly at those figures.
    """
    settings = Settings()
    k = np.array([0.0133, 0.0129, 0.0080])
    u_fs = k * np.asarray(settings.full_scale)
    chi = {}
    for name in ("xy", "xz", "yx", "yz", "zx", "zy"):
        amp = coupling / 2 * u_fs[AXES.index(name[0])]
        g = np.e / 2 * (slope / amp) ** 2
        chi[name] = Chi(name, g, np.array([0.0]), np.array([amp]), 0.0, 1.0, 1.0, (-1.5, 1.5), 1)
    return CouplingErrorModel(settings, k, chi)


def test_a_sensor_at_the_papers_limits_sits_at_the_second_order_limit():
    """Section 2.1's sensor (5 % coupling, slopes 0.05) has the 0.25 % bound of eq. (6):
    the second-order limit is what the two other limits imply, and status follows it."""
    at = by_key(bump_model(0.05, 0.05))
    for name in ("xy", "xz", "yx", "yz", "zx", "zy"):
        assert at[("slope", name)].value == pytest.approx(0.05, rel=1e-5)
        assert at[("second_order", name)].value == pytest.approx(0.0025, rel=1e-5)
        assert at[("second_order", name)].limit == pytest.approx(0.0025, rel=1e-12)
    for axis in AXES:
        assert at[("coupling", axis)].value == pytest.approx(0.05, rel=1e-12)  # u = 0 on the grid
    # 1 % under both limits passes every check; 3 % over the slope limit alone warns
    # on the slope and on the second order (0.0495 * 0.0515 = 0.255 %), not on coupling
    under = by_key(bump_model(0.0495, 0.0495))
    assert {c.status for (n, _), c in under.items() if n != "linearity"} == {"pass"}
    over = by_key(bump_model(0.0495, 0.0515))
    for (n, _), c in over.items():
        if n in ("slope", "second_order"):
            assert c.status == "warn", (n, c)
        elif n == "coupling":
            assert c.status == "pass", (n, c)
