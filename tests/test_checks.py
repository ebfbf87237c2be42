"""Assumption checks of Section 2.1 and the eq. (6) bound."""

from __future__ import annotations

import numpy as np

from fsdecouple.checks import SECOND_ORDER_LIMIT, assumption_checks, chi_slope


def test_slope_matches_finite_difference(model):
    for c in model.chi.values():
        lo, hi = c.input_range
        u = np.linspace(lo, hi, 101)
        # h balances roundoff (the dual coefficients, up to C = 1000, cancel:
        # ~1e-16 * sum|c| / h) against truncation (h^2 * third derivative / 6)
        h = 1e-4
        numeric = (c(u + h) - c(u - h)) / (2 * h)
        np.testing.assert_allclose(chi_slope(c, u), numeric, rtol=0, atol=1e-6)


def test_checks_on_simulated_sensor(model, sensor):
    checks = {(c.name, c.subject): c for c in assumption_checks(model)}
    assert len(checks) == 3 + 3 + 6 + 6
    # the simulated coupling is 1.1-2.7 % F.S. per pair, so per channel it is the
    # sum of two pair amplitudes (noise adds a little)
    for a, axis in enumerate("xyz"):
        truth = sum(sensor.amplitude[a])
        assert abs(checks[("coupling", axis)].value - truth) < 0.005
        assert checks[("coupling", axis)].status == "pass"
    assert all(checks[("linearity", a)].status == "pass" for a in "xyz")
    # eq. (6): the bound is the product of the slope and the input's coupling
    for name in ("xy", "zx"):
        expected = checks[("slope", name)].value * checks[("coupling", name[1])].value
        assert checks[("second_order", name)].value == expected
    assert checks[("second_order", "xy")].limit == SECOND_ORDER_LIMIT == 0.05 * 0.05


def test_second_order_bound_holds_on_task_data(model, sim_dir):
    """The measured second-order error |chi(u_t) - chi(u_aa)| / u_FS obeys the bound."""
    import pandas as pd

    from fsdecouple.simulate import SimulatedSensor

    s = SimulatedSensor()
    f = pd.read_csv(sim_dir / "task_forces.csv")[["fx", "fy", "fz"]].to_numpy()
    u_t = s.voltages(f)  # noise-free task voltages
    u_prime = f * s.k  # the prime voltages u_aa
    u_fs = np.abs(model.k) * np.array([100.0, 100.0, 150.0])
    checks = {(c.name, c.subject): c.value for c in assumption_checks(model)}
    for name, c in model.chi.items():
        b = "xyz".index(name[1])
        err = np.abs(c(u_t[:, b]) - c(u_prime[:, b])) / u_fs[b]
        assert err.max() <= checks[("second_order", name)] * 1.05
