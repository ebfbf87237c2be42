"""Temperature drift of a calibration set: per output channel an offset drift b_i and a
gain drift g_i about a reference temperature T0 (issue 31, ATI's form,
:mod:`fsdecouple.core.temperature`):

    u_i,measured = (1 + g_i (T - T0)) u_i(T0) + b_i (T - T0)

where u_i(T0) is the raw reading at T0, the channel's zero offset z_i included.

The offset drift is seen before zero correction: the raw readings of every row, zero
rows (and a soak's rows, every load zero) included, are fitted per channel i, in
normalised units (y = u / u_FS, each output's full-scale output), by

    y = z + beta dT + (1 + g dT) s(F),     dT = T - T0,

jointly with a forward model of the loads s(F) (one value per load point of the
calibration grid, shared by every temperature; a degree-5 polynomial per component
when the loads are not on a grid), so the offset at each sweep's temperature, the
gain change of the loaded rows and the channel's response are one least-squares fit
(Gauss-Newton from g = 0).  Then b = beta - g z (the gain acts on the offset too in
ATI's form).  Uncertainties: the fit's covariance, scaled by its residual scatter,
and inflated when the sweeps' offsets scatter about the line more than their noise
says (an offset that also jumps between sweeps).

The decoupling model is then fitted on the set's outputs corrected to T0,
``correct(raw, T) - correct(zero_s, T_s)`` per sweep s (:func:`compensate`), and the
terms go into the model (:class:`~fsdecouple.core.temperature.TemperatureTerms`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from ..core.temperature import TemperatureTerms, correct
from ..temperature_units import MIN_SPAN, MODEL_UNIT

if TYPE_CHECKING:
    from ..data.calibration import CalibrationSet

LEVEL_GAP = MIN_SPAN / 2  # sweeps this far apart in temperature are different levels
POLY_DEGREE = 5
ITERATIONS = 8
# sweep-mean residuals within this many times their noise (in variance): the offsets follow
# z + beta dT, so every row's fit of z zeroes the set better than one zero row a sweep
STEADY_SCATTER = 4.0


@dataclass(frozen=True)
class ChannelFit:
    """One output's fit, in normalised units (y = u / u_FS)."""

    z: float
    beta: float
    g: float
    cov: np.ndarray  # (3, 3) of (z, beta, g)
    sweep_scatter: float  # sweep-mean residuals' excess over their noise (>= 1)


def has_temperature(calib: CalibrationSet) -> bool:
    return "temperature" in calib.points.columns


def sweep_ids(points) -> np.ndarray:
    return points.groupby(["repetition", "axis"], sort=True).ngroup().to_numpy()


def levels(t_sweep: np.ndarray) -> list[np.ndarray]:
    """Sweep indices grouped by temperature level (sorted; gaps > LEVEL_GAP split)."""
    order = np.argsort(t_sweep)
    cuts = np.flatnonzero(np.diff(t_sweep[order]) > LEVEL_GAP) + 1
    return np.split(order, cuts)


def _design(forces: np.ndarray, full_scale: np.ndarray) -> np.ndarray:
    """s(F) as a linear model: one column per distinct loaded point of a grid shared by
    repetitions, or a degree-5 polynomial per component (no constant: z holds it)."""
    f = forces / full_scale
    keys = np.round(f, 9)
    loaded = np.any(keys != 0.0, axis=1)
    uniq, inverse = np.unique(keys[loaded], axis=0, return_inverse=True)
    if loaded.any() and len(uniq) <= loaded.sum() / 2:  # a grid visited at least twice a point
        phi = np.zeros((len(f), len(uniq)))
        phi[np.flatnonzero(loaded), inverse.ravel()] = 1.0
        return phi
    return np.column_stack([f[:, j] ** d for j in range(f.shape[1])
                            for d in range(1, POLY_DEGREE + 1)])


def _fit_channel(y: np.ndarray, dt: np.ndarray, phi: np.ndarray, sweep: np.ndarray) -> ChannelFit:
    """y = z + beta dT + (1 + g dT) phi theta by Gauss-Newton from g = 0."""
    n, k = phi.shape
    g = 0.0
    for _ in range(ITERATIONS):  # g dT ~ 1e-3: a handful of steps settle to rounding
        a = np.column_stack([np.ones(n), dt, (1.0 + g * dt)[:, None] * phi])
        p, *_ = np.linalg.lstsq(a, y, rcond=None)
        s = phi @ p[2:]
        r = y - a @ p
        sd = dt * s
        denom = float(sd @ sd)
        step = float(r @ sd) / denom if denom > 0 else 0.0
        g += step
        if abs(step) < 1e-15:
            break
    z, beta, theta = p[0], p[1], p[2:]
    s = phi @ theta
    jac = np.column_stack([np.ones(n), dt, dt * s, (1.0 + g * dt)[:, None] * phi])
    r = y - (z + beta * dt + (1.0 + g * dt) * s)
    dof = max(n - jac.shape[1], 1)
    sigma2 = float(r @ r) / dof
    cov = sigma2 * np.linalg.pinv(jac.T @ jac)[:3, :3]
    # the sweeps' mean residuals against their noise: an offset jumping between sweeps
    ids, counts = np.unique(sweep, return_counts=True)
    means = np.bincount(np.searchsorted(ids, sweep), weights=r) / counts
    chi2 = float(np.sum(means ** 2 * counts) / sigma2) / max(len(ids) - 2, 1) if sigma2 > 0 else 1.0
    return ChannelFit(float(z), float(beta), float(g), cov, max(1.0, chi2))


@dataclass(frozen=True)
class TemperatureFit:
    """What :func:`fit_terms` found, with the figures ``fit`` prints."""

    terms: TemperatureTerms
    levels: list[float]  # mean temperature of each level [degC]
    output_unit: str
    outputs: tuple[str, ...]
    heldout: list[dict[str, Any]] | None = None
    # each output's zero at T0 [output unit] when the sweeps' offsets follow z + beta dT
    # within their noise (else None: each sweep keeps the zero its rows gave)
    offset_t0: np.ndarray | None = None

    def to_dict(self) -> dict[str, Any]:
        t = self.terms
        return {"t0": t.t0, "unit": t.unit, "span": list(t.span), "levels": self.levels,
                "b": dict(zip(self.outputs, map(float, t.b), strict=True)),
                "b_sigma": dict(zip(self.outputs, map(float, t.b_sigma), strict=True)),
                "g": dict(zip(self.outputs, map(float, t.g), strict=True)),
                "g_sigma": dict(zip(self.outputs, map(float, t.g_sigma), strict=True)),
                "output_unit": self.output_unit, "heldout": self.heldout}


def sweep_temperatures(points, sweep: np.ndarray) -> np.ndarray:
    """Each sweep's temperature: the mean over its rows [degC]."""
    t = points["temperature"].to_numpy(dtype=float)
    return np.bincount(sweep, weights=t) / np.bincount(sweep)


def fit_terms(calib: CalibrationSet, settings, *, t0: float | None = None) -> TemperatureFit | None:
    """The temperature terms of ``calib`` (module doc), or None when its sweeps do not
    span two temperatures MIN_SPAN apart."""
    pts = calib.points
    layout = calib.layout
    sweep = sweep_ids(pts)
    t_sweep = sweep_temperatures(pts, sweep)
    groups = levels(t_sweep)
    if len(groups) < 2 or np.ptp(t_sweep) < MIN_SPAN:
        return None
    t = pts["temperature"].to_numpy(dtype=float)
    span = (float(t.min()), float(t.max()))  # the sweeps' span: a soak has no gain
    if t0 is None:  # the middle of the calibrated levels, to 0.1 K
        t0 = round(float(np.mean([t_sweep[g].mean() for g in groups])), 1)
    raw = pts[[f"{c}_raw" for c in layout.outputs]].to_numpy(dtype=float)
    u_fs = np.abs(pts[list(layout.outputs)].to_numpy(dtype=float)).max(axis=0)
    u_fs[~(u_fs > 0)] = 1.0
    forces = pts[list(layout.loads)].to_numpy(dtype=float)
    soak = getattr(calib, "soak", None)
    if soak is not None and len(soak):  # every load zero: one more sweep of offsets only
        t = np.concatenate([t, soak["temperature"].to_numpy(dtype=float)])
        raw = np.vstack([raw, soak[list(layout.outputs)].to_numpy(dtype=float)])
        forces = np.vstack([forces, soak[list(layout.loads)].to_numpy(dtype=float)])
        sweep = np.concatenate([sweep, sweep.max() + 1 + pd.factorize(soak["file"])[0]])
    dt = t - t0
    phi = _design(forces, np.asarray(settings.full_scale, dtype=float))
    m = raw.shape[1]
    b, g, sb, sg, z = (np.zeros(m) for _ in range(5))
    steady = True
    for i in range(m):
        c = _fit_channel(raw[:, i] / u_fs[i], dt, phi, sweep)
        # b = beta - g z; var by the delta method, inflated by the sweeps' excess scatter
        grad = np.array([-c.g, 1.0, -c.z])
        var_b = float(grad @ c.cov @ grad) * c.sweep_scatter
        b[i], sb[i] = (c.beta - c.g * c.z) * u_fs[i], np.sqrt(var_b) * u_fs[i]
        g[i], sg[i] = c.g, np.sqrt(c.cov[2, 2] * c.sweep_scatter)
        z[i] = c.z * u_fs[i]
        steady &= c.sweep_scatter <= STEADY_SCATTER
    terms = TemperatureTerms(m, float(t0), b, g, MODEL_UNIT, span, sb, sg)
    return TemperatureFit(terms, [float(t_sweep[gr].mean()) for gr in groups],
                          settings.output_unit, tuple(layout.outputs), offset_t0=z if steady else None)


def corrected_points(calib: CalibrationSet, terms: TemperatureTerms, offset_t0=None):
    """The set's points with outputs at T0: ``correct(raw, T) - correct(zero_s, T_s)`` per
    sweep s, zero_s the offset the set removed from it and T_s its rows' mean temperature;
    or, given ``offset_t0`` (the fit's zero at T0, from every row of every sweep, when the
    sweeps' offsets follow the drift), ``correct(raw, T) - offset_t0``: a single zero row
    per sweep no longer adds its noise to the sweep's points."""
    pts = calib.points.copy()
    layout = calib.layout
    outs = list(layout.outputs)
    raw = pts[[f"{c}_raw" for c in outs]].to_numpy(dtype=float)
    zeroed = pts[outs].to_numpy(dtype=float)
    offset = raw - zeroed  # each row's sweep offset, as the set removed it
    sweep = sweep_ids(pts)
    t = pts["temperature"].to_numpy(dtype=float)
    t_s = sweep_temperatures(pts, sweep)[sweep]
    b, g = terms.b, terms.g
    zero = correct(offset, t_s, terms.t0, b, g) if offset_t0 is None else offset_t0
    pts[outs] = correct(raw, t, terms.t0, b, g) - zero
    return pts


def compensate(calib: CalibrationSet, settings) -> tuple[CalibrationSet, TemperatureFit | None]:
    """``calib`` with outputs at T0 and the fit, when its temperatures span MIN_SPAN; else
    ``calib`` as it is (a warning said why) and None.  A set compensated already (its
    ``temperature_fit`` set) is returned as it is."""
    if not has_temperature(calib) or getattr(calib, "temperature_fit", None) is not None:
        return calib, getattr(calib, "temperature_fit", None)
    found = fit_terms(calib, settings)
    if found is None:
        t = calib.points["temperature"].to_numpy(dtype=float)
        note = (f"the calibration's temperatures span {np.ptp(t):.3g} K (from {t.min():.4g} to "
                f"{t.max():.4g} degC), less than {MIN_SPAN:g} K between two temperatures: no "
                "temperature terms fitted")
        if note in calib.warnings:  # judged already (fit compensates, then establish)
            return calib, None
        return replace(calib, warnings=(*calib.warnings, note)), None
    found = replace(found, heldout=heldout(calib, settings, found))
    points = corrected_points(calib, found.terms, found.offset_t0)
    return replace(calib, points=points, temperature_fit=found), found


def heldout(calib: CalibrationSet, settings, found: TemperatureFit) -> list[dict[str, Any]]:
    """Fit on the other temperatures, test on one: the worst component's RMS error [% F.S.]
    of each level's points, tared at T0 (the offset at T0 the other levels' fit gives),
    decoupled by a least-squares cubic in the outputs (u, u^2, u^3 of every output: the
    coupling's curvature, cheaper than an SVR fit per level) fitted on the other levels,
    with the temperature terms of the other levels and without any (the raw readings less
    that tare)."""
    from .linear import fit_calibration_matrix

    def cubic(u):
        return np.column_stack([u, u ** 2, u ** 3])

    pts = calib.points
    layout = calib.layout
    sweep = sweep_ids(pts)
    t_sweep = sweep_temperatures(pts, sweep)
    groups = levels(t_sweep)
    fs = np.asarray(settings.full_scale, dtype=float)
    raw_all = pts[[f"{c}_raw" for c in layout.outputs]].to_numpy(dtype=float)
    t_all = pts["temperature"].to_numpy(dtype=float)
    f_all = pts[list(layout.loads)].to_numpy(dtype=float)
    out = []
    for group in groups:
        test = np.isin(sweep, group)
        train = replace(calib, points=pts[~test].reset_index(drop=True))
        other = fit_terms(train, settings, t0=found.terms.t0)
        if other is None:
            continue
        terms = other.terms
        tp = corrected_points(train, terms)
        c_comp = fit_calibration_matrix(cubic(tp[list(layout.outputs)].to_numpy(float)),
                                        train.forces).C
        c_raw = fit_calibration_matrix(cubic(train.voltages), train.forces).C
        # the tare at T0: the offset the other levels' fit puts there, u(T0) of no load
        zero_rows = ~np.any(f_all[~test] != 0.0, axis=1)
        z_t0 = _offset_at_t0(raw_all[~test][zero_rows], t_all[~test][zero_rows], terms)
        raw, t, f = raw_all[test], t_all[test], f_all[test]
        with_terms = cubic(correct(raw, t, terms.t0, terms.b, terms.g) - z_t0) @ c_comp.T
        without = cubic(raw - z_t0) @ c_raw.T

        def worst(pred, f=f):
            return float(100.0 * np.max(np.sqrt(np.mean((pred - f) ** 2, axis=0)) / fs))

        out.append({"temperature": float(t_sweep[group].mean()), "points": int(test.sum()),
                    "worst_rms_pct_fs_without": worst(without),
                    "worst_rms_pct_fs_with": worst(with_terms)})
    return out


def _offset_at_t0(raw0: np.ndarray, t: np.ndarray, terms: TemperatureTerms) -> np.ndarray:
    """The zero reading at T0 from zero rows at temperatures t: mean of correct(raw0, t)."""
    return correct(raw0, t, terms.t0, terms.b, terms.g).mean(axis=0)
