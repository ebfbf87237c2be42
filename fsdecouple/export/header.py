"""Export a model as one dependency-free C99 header (``fsdecouple export``).

The header is the model's decoupling plan (:mod:`fsdecouple.core.plan`: eq. (11),
f_a = (u_a - sum_(b != a) chi_ab(u_b)) / k_aa, with a joint fit's own-load chi_aa(u_a),
refinement, the M > N projection and the rotation) with the header's tables in its
terms: each chi (eq. 4) a cubic Hermite table inside its interval and the exact
kernel sum (eq. 10) over the embedded support vectors outside it, so it agrees with
``model.decouple`` everywhere.  A ``linear`` model's plan is f = C u, with the same
API, status bits and self-test.  This module decides every number the header holds
and checks what it promises against the plan's own evaluators (the exact path,
:func:`exact_forces`, and the float emulation, :func:`emulate_float`, which walk the
same plan as the C); :mod:`fsdecouple.export.c_source` writes the C text.

* Tables: the model's own surrogates when they are within the export's promise,
  or, with ``max_error``, the coarsest uniform tables (resampled from the kernel
  sum and its derivative, checked densely) that keep the force error bound.
* Float: the single-precision function's error bound is measured by a numpy
  float32 emulation of the generated C against the exact model.
* Self-test: reference vectors from the exact model, embedded with tolerances.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np

from ..core.decouple import PROMISE, couple, exact
from ..core.model import FORCE_LIMIT
from ..core.modelfile import model_to_dict
from ..core.plan import Term, walk
from ..core.surrogate import CHECKS_PER_INTERVAL
from ..errors import ConfigError, FsdecoupleError
from ..files.outputs import atomic_write
from .c_function import MAX_CHANNELS
from .c_source import render
from .plan import ExportPlan, ExportResult
from .resample import coarsest_tables, table_bound

PRECISIONS = ("double", "float")
# The double header promises forces within PROMISE of the exact model (a fraction
# of each output's full scale, |df| * |k| / (|k| F_FS)), as model.decouple's table
# path does.  An output sums N - 1 chi tables; each may use half its share, the
# other half covers error between check points and rounding.  For 3 axes this is
# 2.5e-10 of full scale, the table path's own gate.
# The float bound is the largest error seen on the check points times this factor:
# the emulation rounds like the C, op for op, but a compiler may fuse a multiply-add
# (one rounding less, changing a result by <= 1/2 ulp per Horner step) or, on x87,
# keep excess precision, and the maximum may lie between sampled points.  The
# errors are sums of a few roundings of <= 1/2 ulp each, so the observed maximum
# over >= 1e5 points is near the worst case; 2x covers every such difference.
FLOAT_SAFETY = 2.0
FLOAT_RANDOM_POINTS = 100_000
_IDENT = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")


def export_header(
    model, out: str | Path, *, precision: str = "double", prefix: str = "fsd_",
    max_error: float | None = None, limits: Any = None, force: bool = False,
) -> ExportResult:
    """Write ``model`` as a self-contained C99 header ``out``.

    Parameters
    ----------
    precision : {"double", "float"}
        ``fsd_decouple`` (double) or ``fsd_decouple_f`` (float tables, float
        arithmetic inside the tables; the rare kernel sums stay in double).
    prefix : str
        Prefix of every C name; macros use it uppercased (``FSD_``).
    max_error : float, optional
        Force error allowed from the tables, as a fraction of each component's
        full-scale load: the coarsest tables keeping it are built.
    limits : mapping or sequence, optional
        Raw channel limits (lo, hi) for the saturation bit, by channel index or
        name (``ux``); default: ``model.settings.limits`` if the model has them.
    """
    from .. import __version__

    if precision not in PRECISIONS:
        raise ConfigError(f"--precision {precision!r}: expected one of {', '.join(PRECISIONS)}")
    if not _IDENT.match(prefix):
        raise ConfigError(f"--prefix {prefix!r}: expected a C identifier (a letter, then "
                          "letters, digits or '_')")
    if max_error is not None and not (np.isfinite(max_error) and max_error > 0):
        raise ConfigError(f"--max-error {max_error!r}: expected a positive fraction of full scale")
    plan = plan_export(model, precision=precision, prefix=prefix, max_error=max_error,
                       limits=limits, version=__version__)
    text = render(plan)
    with atomic_write(out, force=force) as fh:
        fh.write(text)
    names = {f"{c.out}{c.inp}": (None if c.table is None else c.table.intervals) for c in plan.chis}
    return ExportResult(Path(out), precision, prefix, plan.n, names, plan.table_bytes,
                        plan.kernel_bytes, plan.table_max_error,
                        plan.float_max_error if precision == "float" else None, plan.method,
                        bool(getattr(model, "imported", False)))


def plan_export(model, *, precision: str = "double", prefix: str = "fsd_",
                max_error: float | None = None, limits: Any = None, version: str = "") -> ExportPlan:
    """Every number of the header, checked: tables, thresholds, bounds, self-test."""
    k = np.asarray(model.k, dtype=float)
    n = k.size
    if n > MAX_CHANNELS:
        raise ConfigError(f"the model has {n} channels; the status word holds at most {MAX_CHANNELS}")
    settings = model.settings
    doc = _model_document(model)
    fs = np.asarray(settings.full_scale, dtype=float)
    cal = np.asarray(model.calibrated_range, dtype=float)
    plan = ExportPlan(
        prefix=prefix, precision=precision, plan=model.plan(),
        full_scale=fs, calibrated_range=cal,
        range_limits=np.asarray(model.extrapolation_limits()),  # exactly apply's "extrapolated"
        limits=_limits(model, limits, getattr(model, "n_inputs", model.n_outputs)),
        digest=str(doc["integrity"]["digest"]), format_version=int(doc["format_version"]),
        sensor=str(settings.sensor), load_unit=settings.load_unit,
        output_unit=settings.output_unit, version=version, model=model,
    )
    if max_error is None:
        u_fs = np.abs(k) * fs  # the promise is a fraction of each output's full scale
        share = PROMISE / (2 * plan.terms_per_output)
        plan.plan = plan.plan.with_terms(
            [t if t.table is not None and t.table.max_error <= share * u_fs[t.out]
             else Term(t.out, t.inp, t.chi, None) for t in plan.chis])
    elif plan.chis:
        # float: the measured bound is FLOAT_SAFETY x (table + rounding error), so the
        # tables get a quarter, leaving the rest of E for float rounding
        share = max_error / (2 * FLOAT_SAFETY) if precision == "float" else max_error
        coarsest_tables(plan, share, max_error)
    plan.table_max_error = float(np.max(table_bound(plan)))
    if max_error is not None and plan.table_max_error > max_error:
        raise FsdecoupleError(f"--max-error {max_error:g}: the tables reach only "
                              f"{plan.table_max_error:.3g} of full scale")
    # for a float u: u < lo  <=>  u < (smallest float >= lo), u > hi  <=>  u > (largest float <= hi)
    plan.range_limits_f = np.column_stack([_f32_up(plan.range_limits[:, 0]),
                                           _f32_down(plan.range_limits[:, 1])])
    if plan.temperature is not None and plan.temperature.span is not None:
        lo, hi = plan.temperature.span  # apply's extrapolated: T < lo or T > hi, as above
        plan.temperature_span_f = (float(_f32_up(lo)), float(_f32_down(hi)))
    # u <= lo  <=>  u <= (largest float <= lo); u >= hi  <=>  u >= (smallest float >= hi)
    plan.limits_f = [(None, None) if a is None else (float(_f32_down(a)), float(_f32_up(b)))
                     for a, b in plan.limits]
    if precision == "float":
        plan.float_max_error = float_bound(plan)
        if max_error is not None and plan.float_max_error > max_error:
            raise FsdecoupleError(f"--max-error {max_error:g}: the float function reaches "
                                  f"{plan.float_max_error:.3g} of full scale with float rounding; "
                                  "use --precision double")
    _selftest(plan)
    return plan


def _model_document(model) -> dict[str, Any]:
    """The model file's document (digest and format_version are read from it)."""
    return model_to_dict(model)


def _limits(model, limits, n: int) -> list:
    """(lo, hi) per channel, (None, None) where no limit is given."""
    if limits is None:
        limits = model.settings.limits  # {'ux': (lo, hi), ...} from the config's limits:
    out: list = [(None, None)] * n
    if not limits:
        return out
    # channel names as the config spells them (ux .. uz, or the config's outputs:)
    names = {name: b for b, name in enumerate(model.layout.outputs)}
    items = limits.items() if hasattr(limits, "items") else enumerate(limits)
    for key, pair in items:
        b = names.get(key, key) if isinstance(key, str) else key
        if not (isinstance(b, int) and 0 <= b < n):
            raise ConfigError(f"limits: unknown channel {key!r}, expected one of "
                              f"{', '.join(sorted(names)) or range(n)}")
        try:
            lo, hi = (float(v) for v in pair)
        except (TypeError, ValueError):
            raise ConfigError(f"limits: {key}: expected [lo, hi], found {pair!r}") from None
        if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
            raise ConfigError(f"limits: {key}: expected finite lo < hi, found [{lo!r}, {hi!r}]")
        out[b] = (lo, hi)
    return out


# --- the reference and the float emulation ----------------------------------------------


def exact_forces(plan: ExportPlan, u: np.ndarray) -> np.ndarray:
    """Forces [N] of the header's plan with every chi exact (the C's reference): the
    model's own exact evaluator (:func:`fsdecouple.core.decouple.exact`); a row whose
    refinement does not settle is NaN, as ``model.decouple`` gives it."""
    return exact(plan.plan, np.asarray(u, dtype=float).reshape(-1, plan.m))


def _float_chi(term: Term, v: np.ndarray) -> np.ndarray:
    """One chi as ``fsd_decouple_f`` evaluates it: the table in float inside it, else the
    kernel sum in double, rounded to float."""
    out = term.chi(v.astype(float)).astype(np.float32)
    if term.table is None:
        return out
    tab = term.table(v, dtype=np.float32)
    return np.where(np.isnan(tab), out, tab)


def emulate_float(plan: ExportPlan, u: np.ndarray) -> np.ndarray:
    """``fsd_decouple_f`` in numpy float32, operation for operation as c_source writes it:
    the header's plan walked in float (:func:`fsdecouple.core.plan.walk`), eq. (11) by
    :func:`fsdecouple.core.decouple.couple` with each chi as :func:`_float_chi`."""
    return walk(plan.plan, np.asarray(u, dtype=np.float32), lambda step, x: couple(
        step, x, _float_chi)[0], dtype=np.float32, evaluator="the float emulation")


def float_bound(plan: ExportPlan, seed: int = 0) -> float:
    """Largest |df| / full scale of the float function on the calibrated range, times safety.

    Points: every channel swept densely (``CHECKS_PER_INTERVAL`` per table interval,
    columns shuffled independently so each row mixes channels), random points and
    the range's corners; inputs rounded to float32 as a float caller holds them.
    """
    rng = np.random.default_rng(seed)
    lo, hi = plan.calibrated_range.T
    m = max([20_001] + [2 * CHECKS_PER_INTERVAL * c.table.intervals for c in plan.chis
                        if c.table is not None])
    dense = [np.column_stack([rng.permutation(np.linspace(lo[b], hi[b], m)) for b in range(plan.n)])
             for _ in range(2)]
    corners = np.array(np.meshgrid(*plan.calibrated_range)).reshape(plan.n, -1).T
    u = np.concatenate([*dense, lo + (hi - lo) * rng.random((FLOAT_RANDOM_POINTS, plan.n)), corners])
    u32 = plan.lift(u, rng).astype(np.float32)  # M > N: outputs whose v = P u spans the range
    u = u32.astype(float)
    err = np.abs(emulate_float(plan, u32).astype(float) - exact_forces(plan, u)) / plan.full_scale
    return FLOAT_SAFETY * float(err.max())


# --- status and self-test ---------------------------------------------------------------


def expected_status(plan: ExportPlan, u: np.ndarray, f: np.ndarray) -> int:
    """The C's status word for one double input ``u`` and its forces ``f``."""
    from .c_function import (
        BIT_INPUT_NOT_FINITE,
        BIT_NOT_CONVERGED,
        BIT_NOT_FINITE,
        BIT_OUTSIDE_TABLE,
        BIT_SATURATED,
        BIT_TEMPERATURE,
    )

    st = 0
    for b, (lo, hi) in enumerate(plan.limits):  # the raw channels
        if lo is not None and (u[b] <= lo or u[b] >= hi):
            st |= 1 << BIT_SATURATED
    if not np.isfinite(u).all():
        st |= 1 << BIT_INPUT_NOT_FINITE
    step = plan.temperature
    if step is not None and step.span is not None and (
            u[step.channel] < step.span[0] or u[step.channel] > step.span[1]):
        st |= 1 << BIT_TEMPERATURE  # apply's "extrapolated" (core/temperature.py)
    row = np.asarray(u, dtype=float).reshape(1, -1)
    u = plan.prime(row)[0]  # the outputs eq. (11) acts on (M > N: v = P u)
    if len(u) == plan.n:
        for b in range(plan.n):
            if u[b] < plan.range_limits[b, 0] or u[b] > plan.range_limits[b, 1]:
                st |= 1 << b
    for c in plan.chis:
        if c.table is not None and not c.table.covers(u[c.inp]):
            st |= 1 << BIT_OUTSIDE_TABLE
    if not (np.abs(f) <= FORCE_LIMIT * np.abs(plan.full_scale).max()).all():
        st |= 1 << BIT_NOT_FINITE  # apply's not_finite: NaN, inf or beyond FORCE_LIMIT x F.S.
    if plan.refine > 0:  # the refinement's settle test, as decouple.settled decides it
        converged = np.empty(1, dtype=bool)
        exact(plan.plan, row, converged)
        if not converged[0]:
            st |= 1 << BIT_NOT_CONVERGED
    return st


def _selftest(plan: ExportPlan) -> None:
    """Reference vectors inside the range (table path), one beyond the tables, one NaN."""
    lo, hi = plan.calibrated_range.T
    mid, half = (lo + hi) / 2, (hi - lo) / 2
    signs = np.array([[1 if (r >> b) & 1 else -1 for b in range(plan.n)] for r in range(4)])
    rows = [mid, *(mid + 0.6 * s * half for s in signs), mid + 0.3 * half * (signs[1] - signs[2])]
    if plan.precision == "double":
        # beyond every table (which reach 25 % of the span past the range): the kernel sums
        far = [max([c.table.hi for c in plan.chis if c.table is not None and c.inp == b],
                   default=-np.inf)
               for b in range(plan.n)]
        rows.append(np.maximum(hi + 0.6 * (hi - lo), np.asarray(far) + 0.1 * (hi - lo)))
    u = plan.lift(np.array(rows))  # M > N: outputs whose v = P u are these rows
    u = np.vstack([u, np.full(plan.m, np.nan)]).astype(np.float32).astype(float)  # float-exact
    with np.errstate(invalid="ignore"):
        f = exact_forces(plan, u)
    plan.selftest_u, plan.selftest_f = u, f
    plan.selftest_status = [expected_status(plan, a, b) for a, b in zip(u, f, strict=True)]
    if plan.precision == "float":
        plan.selftest_tol = plan.float_max_error * plan.full_scale
        plan.selftest_note = ("FSD_FLOAT_MAX_ERROR of full scale, the export-time bound of the "
                              "float function against the exact model")
    else:
        # tables may differ from the kernel sum by their bound; 1e-9 of full scale more
        # covers libm's exp and summation order (~1e-12 of full scale) with a wide margin
        # while any wrong constant, sign or table entry shows up far above it
        plan.selftest_tol = (plan.table_max_error + 1e-9) * plan.full_scale
        plan.selftest_note = "(FSD_TABLE_MAX_ERROR + 1e-9) of full scale: tables plus rounding"


def _f32_down(x):
    """Largest float32 <= x (as float64)."""
    x = np.asarray(x, dtype=float)
    y = x.astype(np.float32)
    y = np.where(y.astype(float) > x, np.nextafter(y, np.float32(-np.inf)), y)
    return y.astype(float)


def _f32_up(x):
    """Smallest float32 >= x (as float64)."""
    x = np.asarray(x, dtype=float)
    y = x.astype(np.float32)
    y = np.where(y.astype(float) < x, np.nextafter(y, np.float32(np.inf)), y)
    return y.astype(float)
