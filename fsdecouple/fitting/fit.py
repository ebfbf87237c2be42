"""Establish the coupling error model from a calibration set (Section 2.3, steps 1-4).

Step 2 fits the omega slopes (eq. 2, :mod:`fsdecouple.fitting.linear`); step 3 fits each
corrected coupling function chi_ab (eq. 4) by its own epsilon-SVR on the b sweeps
(:mod:`fsdecouple.fitting.svr`, Table 2); the chi tables of the fast path are built after
the fit (:mod:`fsdecouple.core.surrogate`).  The result carries a :class:`FitReport`.
"""

from __future__ import annotations

import functools
import os
import platform
from dataclasses import replace
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..config import Settings
from ..core.decouple import MAX_SURROGATE_ERROR, usable
from ..core.extrapolation import table_interval as tangent_interval
from ..core.metrics import interference_errors
from ..core.model import Chi, CouplingErrorModel, FitReport
from ..core.surrogate import TOLERANCE, build_pair, table_interval
from ..errors import InputError, where
from .joint import backfit, check_separable, joint_svr, multi_load
from .linear import fit_omega
from .noise import solver_tolerance
from .threads import single_threaded_libraries, thread_pool

if TYPE_CHECKING:
    from ..data.calibration import CalibrationSet

# Kernel input span, in kernel widths delta, outside which Table 2's gamma is a
# poor match for the data's units (volts of order 1 give a span of about 3).
KERNEL_SPAN_RANGE = (0.1, 30.0)


def _library_versions() -> dict[str, str]:
    return dict(_installed_versions())  # a copy: each model owns its provenance


@functools.cache
def _installed_versions() -> dict[str, str]:
    # reading package metadata costs ~5 ms; cv fits dozens of models
    out = {"python": platform.python_version()}
    for dist in ("numpy", "scipy", "pandas", "libsvm-official"):
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[dist] = "not installed"
    return out


def provenance(calib: CalibrationSet) -> dict:
    """The files a model was fitted on, the libraries, the lines left out, and how a set
    loading several components a row was zeroed (``before``: each row by the nearest zero
    row before it, data/zero.py), the one choice of the set that no config value names."""
    out = {"files": [{"path": p, "sha256": h} for p, h in calib.files],
           "libraries": _library_versions()}
    if calib.excluded:
        out["excluded"] = list(calib.excluded)
    if getattr(calib, "zero", None) == "before":
        out["zero"] = "before"
    return out


def chi_training_data(calib: CalibrationSet, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(prime voltage, coupling error element) of chi_ab from the b sweeps, file order.

    Section 2.1: in the b-direction calibration data u_b = u_bb and u_a = e_ab.
    """
    layout = calib.layout
    a, b = layout.pair(name)
    prime, coupling = calib.sweep_columns(layout.labels[b], [layout.outputs[b], layout.outputs[a]])
    return prime.astype(float, copy=False), coupling.astype(float, copy=False)


def fit(
    calib: CalibrationSet | str | Path,
    settings: Settings | None = None,
    *,
    workers: int | None = None,
    tables: bool = True,
    noise_fraction: float | None = None,
) -> CouplingErrorModel:
    """Establish the coupling error model (Section 2.3, steps 1-4).

    Parameters
    ----------
    calib : CalibrationSet or path
        Zero-corrected calibration set, or a path to read one from.
    settings : Settings, optional
        Defaults to the paper's sensor and Table 2.
    workers : int, optional
        Threads training the N(N - 1) SVRs (libsvm releases the GIL); default: the
        number of cores.  The result does not depend on it.
    tables : bool
        Build the chi tables of the fast path.  A model fitted only to be scored
        on held-out points (the verdict, cv) decouples exactly without them.
    noise_fraction : float, optional
        The built-in solver tolerance's fraction of the noise sigma
        (:func:`fsdecouple.fitting.noise.solver_tolerance`); default: its own.
    """
    # fitting needs pandas (calibration) and libsvm; loading and applying a model do not
    from ..data.calibration import CalibrationSet, load_calibration
    from .svr import fit_svr  # the only libsvm user
    from .temperature import compensate

    settings = settings or Settings()
    if not isinstance(calib, CalibrationSet):
        calib = load_calibration(calib, settings)
    with single_threaded_libraries():  # the terms' least squares too (threads.py)
        # a temperature column spanning >= 5 K: the outputs at T0, and the terms (issue 31)
        calib, drift = compensate(calib, settings)
        model = _establish(calib, settings, workers, fit_svr, tables, noise_fraction)
    if drift is not None:
        model.temperature = drift.terms
        model.report.temperature = drift.to_dict()
    return model


def _svr_chi(s) -> Chi:
    """A fitted SVR as a chi of normalised units, to evaluate while backfitting."""
    return Chi("", s.gamma, s.support_vectors, s.dual_coef, s.rho, pair=(0, 1))


def _omega_failure(calib: CalibrationSet, a: int, settings: Settings) -> str:
    """Why omega_a has no finite non-zero slope: values too large, or a flat sweep.

    k = sum(f u) / sum(f^2) (eq. 2): sums that overflow a double give an infinite,
    NaN or zero k too, and that is not a voltage that does not change.
    """
    layout = calib.layout
    axis = layout.labels[a]
    s = calib.sweep(axis)
    f = s[layout.loads[a]].to_numpy(dtype=float)
    u = s[layout.outputs[a]].to_numpy(dtype=float)
    with np.errstate(over="ignore", invalid="ignore"):
        sums = (float(f @ f), float(f @ u))
    if not np.isfinite(sums).all():
        return (f"{_largest_cell(s, [layout.loads[a], layout.outputs[a]], settings)} is too "
                f"large: the sums of eq. (2) over the {axis} sweeps overflow a double, so "
                f"omega_{axis} cannot be fitted; check the data's units and the config's scale key")
    return (f"{calib.source}: the {axis} sweeps' prime voltage {layout.outputs[a]} does not "
            f"change with {layout.loads[a]}; cannot fit omega_{axis} (eq. 2)")


def _largest_cell(points, columns: list[str], settings: Settings | None) -> str:
    """``FILE, row N, column 'HEADER': VALUE``: the cell of largest magnitude among
    ``columns`` of ``points``, named as the user's file names it (the config's columns:)
    and as it reads there (an output before its zero correction)."""
    raw = [f"{c}_raw" if f"{c}_raw" in points.columns else c for c in columns]
    values = points[raw].abs().to_numpy(dtype=float)
    i, j = np.unravel_index(int(np.argmax(values)), values.shape)
    at = points.iloc[i]
    header = (settings.columns.get(columns[j], columns[j]) if settings is not None
              else columns[j])
    return (f"{where(at['file'], int(at['row']), header)}: {float(at[raw[j]]):.6g}")


def _establish(calib: CalibrationSet, settings: Settings, workers: int | None,
               fit_svr, with_tables: bool, noise_fraction: float | None = None
               ) -> CouplingErrorModel:
    layout = settings.layout
    if calib.layout != layout:
        raise InputError(f"{calib.source}: read for components {', '.join(calib.layout.loads)}, "
                         f"but the settings name {', '.join(layout.loads)}")
    if layout.overdetermined:  # M > N: a forward model per output (gauges.py)
        return _establish_gauges(calib, settings, workers, fit_svr, with_tables)
    labels, pairs = layout.labels, dict(zip(layout.chi_names, layout.pairs, strict=True))
    omega = fit_omega(calib.points, layout)
    if calib.zero == "intercept" and multi_load(calib.forces):
        # poses of a mass: no row isolates a load, so each prime output's slope (eq. 2) is
        # its load's coefficient in the least-squares fit of the output on every load
        coef, *_ = np.linalg.lstsq(calib.forces, calib.voltages, rcond=None)
        omega = replace(omega, k=np.diag(coef).copy())
    warnings = list(calib.warnings)
    for a, axis in enumerate(labels):
        if not np.isfinite(omega.k[a]) or omega.k[a] == 0.0:
            raise InputError(_omega_failure(calib, a, settings))
        if not omega.r2[a] >= settings.min_r2:
            warnings.append(
                f"omega_{axis}: R^2 = {omega.r2[a]:.5f} is below {settings.min_r2} "
                "(assumption 1 of Section 2.1: prime force and voltage are linear)"
            )
    # Kernel scaling: "full_scale" divides inputs and targets by each axis's
    # full-scale output |k| F_FS [V], so Table 2's gamma suits mV or ADC counts too.
    if settings.scaling == "full_scale":
        scale = np.abs(omega.k) * np.asarray(settings.full_scale)
    else:
        scale = np.ones(layout.n)
    settings = solver_tolerance(calib, settings, omega.k, scale,  # noise.py
                                **({} if noise_fraction is None
                                   else {"noise_fraction": noise_fraction}))
    jobs = []
    for name, (o, i) in pairs.items():
        x, y = chi_training_data(calib, name)
        jobs.append((name, x, y, float(scale[i]), float(scale[o])))
    joint = multi_load(calib.forces)  # rows loading several components (joint.py)
    if joint:
        check_separable(calib.forces, settings.full_scale, layout.loads, calib.source)
    for a, axis in enumerate(labels):
        rows = calib.points if joint else calib.sweep(axis)  # a joint fit's chi see every row
        x = rows[layout.outputs[a]].to_numpy() / scale[a]
        span = (x.max() - x.min()) * np.sqrt(2.0 * settings.svr.gamma)
        lo, hi = KERNEL_SPAN_RANGE
        if not lo <= span <= hi:
            warnings.append(
                f"chi inputs from {layout.outputs[a]} span {span:.3g} kernel widths (expected "
                f"{lo:g} to {hi:g} for delta^2 = {settings.svr.delta2:g}); the voltages may "
                "be in mV or ADC counts: set 'scaling: full_scale' in the config"
            )

    def one(job):
        name, x, y, in_scale, out_scale = job
        s = fit_svr(x / in_scale, y / out_scale, settings.svr)
        if not all(np.isfinite(v).all() for v in (s.dual_coef, s.rho, s.support_vectors)):
            raise _overflow(calib, f"the fit of chi_{name}", settings)
        return Chi(
            name, s.gamma, s.support_vectors, s.dual_coef, s.rho, in_scale, out_scale,
            (float(x.min()), float(x.max())), int(x.size), extrapolation=settings.extrapolation,
            pair=None if layout.is_default else pairs[name],
        )

    u_fs = np.abs(omega.k) * np.asarray(settings.full_scale)

    def tables(axis: str) -> list[Chi]:
        # the chi fed by one input axis share one grid (one index per input value), an
        # own-load chi_aa of a joint fit included; the tolerance is a fraction of the
        # full-scale output of the chi's output
        pair = [c for c in [*chis, *own.values()] if labels[c.input_axis] == axis]
        # tangent tables have knots at the range's ends (extrapolation.table_interval)
        interval = tangent_interval if settings.extrapolation == "tangent" else table_interval
        lo, hi = interval(min(c.input_range[0] for c in pair), max(c.input_range[1] for c in pair))
        tolerance = TOLERANCE * min(u_fs[c.output_axis] for c in pair)
        return [replace(c, surrogate=s)
                for c, s in zip(pair, build_pair(pair, lo, hi, tolerance), strict=True)]

    def output(a: int) -> tuple[float, list[Chi]]:
        # eq. (11) rearranged, fitted from multi-load rows by backfitting (joint.py)
        u, f = calib.voltages, calib.forces
        fn, un = f / np.asarray(settings.full_scale), u / scale
        sigma = None if calib.noise is None else float(calib.noise[a] / scale[a])  # pose logs
        svr = joint_svr(settings.svr, fn, un, a, sigma)
        k, fitted = backfit(fn, un, a, lambda x, y: _svr_chi(fit_svr(x, y, svr)), own=True)
        out = []
        for b, c in fitted.items():
            x = u[:, b]
            out.append(Chi(layout.chi_name(a, b), c.gamma, c.support_vectors, c.dual_coef,
                           c.rho, float(scale[b]), float(scale[a]),
                           (float(x.min()), float(x.max())), int(x.size),
                           extrapolation=settings.extrapolation,
                           pair=None if layout.is_default else (a, b)))
        return k * scale[a] / settings.full_scale[a], out

    n_workers = workers or min(len(jobs), os.cpu_count() or 1)
    own: dict[str, Chi] = {}
    if joint:
        with thread_pool(max(1, min(n_workers, layout.n))) as pool:
            per_output = list(pool.map(output, range(layout.n)))
        omega = replace(omega, k=np.array([k for k, _ in per_output]))
        chis = [c for _, cs in per_output for c in cs if c.output_axis != c.input_axis]
        own = {c.name: c for _, cs in per_output for c in cs if c.output_axis == c.input_axis}
        if with_tables:
            with thread_pool(max(1, min(n_workers, layout.n))) as pool:
                tabled = [c for pair in pool.map(tables, labels) for c in pair]
            done = [c for c in tabled if c.output_axis != c.input_axis]
            own = {c.name: c for c in tabled if c.output_axis == c.input_axis}
        else:
            done = chis
    elif n_workers > 1:
        with thread_pool(n_workers) as pool:
            chis = list(pool.map(one, jobs))
            done = [c for pair in pool.map(tables, labels) for c in pair] if with_tables else chis
    else:
        chis = [one(j) for j in jobs]
        done = [c for axis in labels for c in tables(axis)] if with_tables else chis
    by_name = {c.name: c for c in done}
    for c in [*done, *own.values()] if with_tables else ():
        if not usable(c.surrogate, u_fs[c.output_axis]):
            warnings.append(
                f"chi_{c.name}: its surrogate table reaches only "
                f"{c.surrogate.max_error / u_fs[c.output_axis]:.2g} of the full-scale output of "
                f"the kernel sum (needs <= {MAX_SURROGATE_ERROR:g}); this model decouples by the "
                "exact kernel sum, about 100x slower"
            )
    model = CouplingErrorModel(settings, omega.k, {name: by_name[name] for name in pairs},
                               own=own)
    u = calib.voltages
    units = settings.units.loads or None
    before = interference_errors(calib.points, model.initial_forces(u), settings.full_scale,
                                 layout, units)
    forces = settled_forces(model, u)
    after = interference_errors(calib.points, forces, settings.full_scale, layout, units)
    if not all(np.isfinite(v) for g in (before, after) for v in g.values()):
        raise _overflow(calib, "gamma (eq. 12) on the calibration points", settings)
    model.report = FitReport(
        r2=dict(zip(labels, map(float, omega.r2), strict=True)),
        n_points=dict(zip(labels, map(int, omega.n), strict=True)),
        n_support_vectors={c.name: int(c.support_vectors.size) for c in [*chis, *own.values()]},
        surrogate_max_error={n: c.surrogate.max_error for n, c in [*model.chi.items(),
                                                                   *model.own.items()]}
        if with_tables else None,
        gamma_before=before,
        gamma_after=after,
        repetitions=calib.repetitions,
        warnings=warnings,
    )
    model.provenance = provenance(calib)
    model.zero = fitted_zero(calib)
    model.created = datetime.now(UTC).replace(microsecond=0).isoformat()
    return model


def _tables_for(chis: list[Chi], settings: Settings, u_fs: np.ndarray, workers: int) -> list[Chi]:
    """The surrogate tables of ``chis``: those fed by one input share one grid (fit's rule)."""
    interval = tangent_interval if settings.extrapolation == "tangent" else table_interval
    n = len(u_fs)

    def one(b: int) -> list[Chi]:
        group = [c for c in chis if c.input_axis == b]
        lo, hi = interval(min(c.input_range[0] for c in group), max(c.input_range[1] for c in group))
        tolerance = TOLERANCE * min(u_fs[c.output_axis] for c in group)
        return [replace(c, surrogate=s)
                for c, s in zip(group, build_pair(group, lo, hi, tolerance), strict=True)]

    with thread_pool(max(1, min(workers, n))) as pool:
        return [c for group in pool.map(one, range(n)) for c in group]


def _establish_gauges(calib: CalibrationSet, settings: Settings, workers: int | None,
                      fit_svr, with_tables: bool) -> CouplingErrorModel:
    """M > N outputs: eq. (11) on v = K^+ u, each output's chi merged (gauges.py)."""
    from .gauges import SOLVE_FRACTION, fit_forward, projection

    layout = settings.layout
    f, u = calib.forces, calib.voltages
    fs = np.asarray(settings.full_scale, dtype=float)
    check_separable(f, fs, layout.loads, calib.source)
    k_fwd, p = projection(f, u, fs, layout.outputs, layout.loads, calib.source)
    if settings.svr.tolerance is None:  # a tolerance written is obeyed; the model records it
        settings = replace(settings, svr=replace(settings.svr, tolerance=SOLVE_FRACTION))
    svr = settings.svr
    n_workers = max(1, workers or min(layout.m, os.cpu_count() or 1))
    with thread_pool(n_workers) as pool:
        v, merged, _ = fit_forward(f, u, fs, p, k_fwd, svr, fit_svr, pool.map, calib.noise)
    chis = [Chi(layout.chi_name(a, b), gamma, sv, coef, rho, float(fs[b]), float(fs[a]),
                (float(v[:, b].min()), float(v[:, b].max())), len(v),
                extrapolation=settings.extrapolation, pair=(a, b))
            for (a, b), (gamma, sv, coef, rho) in merged.items()]
    for c in chis:
        if not all(np.isfinite(x).all() for x in (c.dual_coef, c.rho, c.support_vectors)):
            raise _overflow(calib, f"the fit of chi_{c.name}", settings)
    warnings = list(calib.warnings)
    if with_tables:
        chis = _tables_for(chis, settings, fs, n_workers)
        warnings += [f"chi_{c.name}: its surrogate table reaches only "
                     f"{c.surrogate.max_error / fs[c.output_axis]:.2g} of full scale (needs <= "
                     f"{MAX_SURROGATE_ERROR:g}); this model decouples by the exact kernel sum"
                     for c in chis if not usable(c.surrogate, fs[c.output_axis])]
    own = {c.name: c for c in chis if c.output_axis == c.input_axis}
    cross = {c.name: c for c in chis if c.output_axis != c.input_axis}
    model = CouplingErrorModel(settings, np.ones(layout.n), {n: cross[n] for n in layout.chi_names},
                               own=own, projection=p)
    units = settings.units.loads or None
    exact = model.decouple(u, rotate=False, exact=True)
    before = interference_errors(calib.points, v, fs, layout, units)
    after = interference_errors(calib.points, exact, fs, layout, units)
    r2 = 1.0 - ((v - f) ** 2).sum(axis=0) / ((v - v.mean(axis=0)) ** 2).sum(axis=0)
    model.report = FitReport(
        r2=dict(zip(layout.labels, map(float, r2), strict=True)),
        n_points={a: int((f[:, i] != 0).sum()) for i, a in enumerate(layout.labels)},
        gamma_before=before, gamma_after=after,
        n_support_vectors={c.name: int(c.support_vectors.size) for c in chis},
        surrogate_max_error={c.name: c.surrogate.max_error for c in chis} if with_tables else None,
        repetitions=calib.repetitions, warnings=warnings,
    )
    model.provenance = provenance(calib)
    model.zero = fitted_zero(calib)
    model.created = datetime.now(UTC).replace(microsecond=0).isoformat()
    return model


def settled_forces(model: CouplingErrorModel, u: np.ndarray) -> np.ndarray:
    """``model``'s forces of the calibration outputs ``u`` (exact), refused in one line
    where its refinement does not settle on every point: eqs. (5)-(6)'s fixed point does
    not hold at such couplings, and their forces would be NaN."""
    settled = np.ones(len(u), dtype=bool)
    forces = model.decouple(u, rotate=False, exact=True, converged=settled)
    if not settled.all():
        raise InputError(
            f"refine {model.settings.refine}: the second-order refinement does not settle on "
            f"{int((~settled).sum())} of the {len(u)} calibration points (the coupling is too "
            "strong for its fixed-point steps); use refine 0, eq. (11) as the paper writes it")
    return forces


def fitted_zero(calib: CalibrationSet) -> np.ndarray | None:
    """``zero: intercept``: the outputs' offsets the model carries (raw output units), the
    mean over the repetitions of each one's fitted intercept (data/zero.py); else None."""
    if calib.zero != "intercept":
        return None
    return calib.offsets[list(calib.layout.outputs)].to_numpy(dtype=float).mean(axis=0)


def _overflow(calib: CalibrationSet, what: str, settings: Settings | None = None) -> InputError:
    """``what`` came out infinite: name the calibration cell of largest magnitude."""
    cell = _largest_cell(calib.points, list(calib.layout.outputs), settings)
    return InputError(f"{cell} makes {what} overflow (not finite); check that cell and the units")
