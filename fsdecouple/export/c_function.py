"""The C decoupling function: the plan's steps printed in order, and the C literals.

:func:`decouple_function` writes the body of ``fsd_decouple`` (``fsd_decouple_f``) as
the steps of the header's plan (:mod:`fsdecouple.core.plan`), one case per step kind
(:func:`_step`); a kind without a case raises
:class:`~fsdecouple.core.plan.UnknownStep` instead of being left out.  Eq. (11) is
written as :func:`fsdecouple.core.decouple.couple` orders it (base = u - chi_own(u),
K refinement steps, k f = base - sum chi), so the float emulation
(``export/header.py``) rounds as the compiled function does.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.model import FORCE_LIMIT
from ..core.plan import (
    Couple,
    InputCorrection,
    Linear,
    Project,
    Rotate,
    TemperatureCorrection,
    UnknownStep,
)
from .plan import ExportPlan

# Status bits above the per-channel range bits (channels 0 .. MAX_CHANNELS - 1).
MAX_CHANNELS = 16
BIT_OUTSIDE_TABLE, BIT_INPUT_NOT_FINITE, BIT_NOT_FINITE, BIT_SATURATED = 16, 17, 18, 19
BIT_NOT_CONVERGED = 20
BIT_TEMPERATURE = 21  # the temperature input beyond the calibrated span


def c_string(text: str) -> str:
    """``text`` as a C string literal: printable ASCII kept, every other byte octal.

    Octal escapes are always three digits (a hex escape would swallow a following
    hex digit); ``?`` is escaped so no trigraph can form.
    """
    out = []
    for byte in text.encode("utf-8"):
        ch = chr(byte)
        if ch in '"\\?' or not 0x20 <= byte < 0x7F:
            out.append(f"\\{byte:03o}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def _fabs(ctype: str) -> str:
    """|x| in the header's own precision: fabsf on floats (no promotion to double, which
    a single-precision FPU does in software)."""
    return "fabsf" if ctype == "float" else "fabs"


def num(x: float) -> str:
    """A double literal that reads back as exactly ``x`` (shortest round-trip repr)."""
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"cannot write {x!r} as a C constant")
    return repr(x)


def numf(x: float) -> str:
    """A float literal of ``x`` rounded to float32 (its repr reads back as that float)."""
    return num(float(np.float32(x))) + "f"


def _chi_call(plan: ExportPlan, j: int, ctype: str, arg: str) -> str:
    term = plan.chis[j]
    f = "f" if ctype == "float" else ""
    if term.table is None:
        return f"({ctype}){plan.prefix}kernel{j}((double){arg})" if ctype == "float" \
            else f"{plan.prefix}kernel{j}({arg})"
    return f"{plan.prefix}chi{f}{j}({arg}, &st)"


def _chi_sum(plan: ExportPlan, a: int, ctype: str, x: str, own: bool) -> str | None:
    """sum of chi_ab(x_b) into output a in the plan's order: the cross chi, or (``own``)
    a joint fit's own-load chi_aa (fitting/joint.py); None if there are none."""
    terms = [_chi_call(plan, j, ctype, f"{x}[{c.inp}]")
             for j, c in enumerate(plan.chis) if c.out == a and c.own == own]
    return " + ".join(terms) if terms else None


def _products(name: str, m: np.ndarray, x: str, fmt) -> list[str]:
    """``name[i] = sum_j m[i][j] x[j]``, the products added left to right."""
    return [f"    {name}[{i}] = " + " + ".join(f"{fmt(m[i][j])} * {x}[{j}]" for j in range(m.shape[1]))
            + ";" for i in range(m.shape[0])]


def _range_bits(plan: ExportPlan, ctype: str, x: str) -> list[str]:
    """Bit b: prime output b outside its calibrated range widened (apply's "extrapolated")."""
    fmt = numf if ctype == "float" else num
    out = []
    for b in range(plan.n):
        lo, hi = plan.range_limits[b] if ctype == "double" else plan.range_limits_f[b]
        out.append(f"    if ({x}[{b}] < {fmt(lo)} || {x}[{b}] > {fmt(hi)}) st |= (uint32_t)1 << {b};")
    return out


def _couple(plan: ExportPlan, step: Couple, ctype: str, x: str, out: str) -> list[str]:
    """Eq. (11) with own-load chi and refinement, as core.decouple.couple orders it:
    base = u - chi_own(u); p <- base - chi(p), K times; k f = base - chi(p)."""
    n, fmt = plan.n, numf if ctype == "float" else num
    lines = [f"    {ctype} base[{n}], {out}[{n}];"]
    for a in range(n):
        own = _chi_sum(plan, a, ctype, x, own=True)
        lines.append(f"    base[{a}] = {x}[{a}]" + (f" - ({own});" if own else ";"))
    p = x
    if step.refine > 0:
        # second-order refinement (eqs. 5-6): K fixed-point steps on the prime outputs
        lines += [f"    {ctype} p[{n}], q[{n}];", "    int k, b;",
                  f"    for (b = 0; b < {n}; ++b) p[b] = {x}[b];",
                  f"    for (k = 0; k < {step.refine}; ++k) {{"]
        lines += [f"        q[{a}] = base[{a}] - ({_chi_sum(plan, a, ctype, 'p', own=False) or fmt(0.0)});"
                  for a in range(n)]
        lines += [f"        for (b = 0; b < {n}; ++b) p[b] = q[b];", "    }"]
        p = "p"
    lines.append(f"    {ctype} kf[{n}];")
    for a in range(n):
        cross = _chi_sum(plan, a, ctype, p, own=False)
        lines.append(f"    kf[{a}] = base[{a}]" + (f" - ({cross});" if cross else ";"))
        lines.append(f"    {out}[{a}] = kf[{a}] / {fmt(step.k[a])};  /* eq. (11) */")
    if step.refine > 0:  # settled, as decouple.settled decides: |k_a f_a - p_a| <= tol
        for a in range(n):
            lines.append(f"    if (!({_fabs(ctype)}(kf[{a}] - p[{a}]) <= {fmt(step.step_tol[a])})) "
                         f"st |= (uint32_t)1 << {BIT_NOT_CONVERGED};")
    return lines


def _step(plan: ExportPlan, step, ctype: str, x: str, dim: int, i: int) -> tuple[list[str], str, int]:
    """C lines of one plan step on the vector ``x`` (``dim`` values): (lines, result, size)."""
    fmt = numf if ctype == "float" else num
    if isinstance(step, TemperatureCorrection):
        # core/temperature.py: u_i(T0) = (u_i - b_i (T - T0)) / (1 + g_i (T - T0)), T = x[channel]
        c = step.channel
        z = step.zero_at_t0()
        keep = [j for j in range(dim) if not (step.external and j == c)]
        lines = [f"    {ctype} c{i}[{len(keep)}];", f"    const {ctype} dt{i} = {x}[{c}] - {fmt(step.t0)};"]
        if step.span is not None:  # apply's "extrapolated": beyond the calibrated temperatures
            lo, hi = step.span if ctype == "double" else plan.temperature_span_f
            lines.append(f"    if ({x}[{c}] < {fmt(lo)} || {x}[{c}] > {fmt(hi)}) "
                         f"st |= (uint32_t)1 << {BIT_TEMPERATURE};")
        zero = f"({ctype}){plan.prefix}zero_t0" if ctype == "float" else f"{plan.prefix}zero_t0"
        for o, j in enumerate(keep):
            e = f"({x}[{j}] - {fmt(step.b[j])} * dt{i}) / ({fmt(1.0)} + {fmt(step.g[j])} * dt{i})"
            # the zero set by set_zero (0 until then), corrected at its own temperature
            lines.append(f"    c{i}[{o}] = {e} - " + (f"{zero}[{j}];" if z is None else f"{fmt(z[j])};"))
        return lines, f"c{i}", len(keep)
    if isinstance(step, InputCorrection) and step.zero:
        # the zero on raw outputs: the model's fitted offsets until set_zero replaces them
        zero = f"({ctype}){plan.prefix}zero" if ctype == "float" else f"{plan.prefix}zero"
        lines = [f"    {ctype} c{i}[{dim}];"]
        lines += [f"    c{i}[{j}] = {x}[{j}] - {zero}[{j}];" for j in range(dim)]
        return lines, f"c{i}", dim
    if isinstance(step, InputCorrection):  # per raw output, before eq. (11)
        lines = [f"    {ctype} c{i}[{dim}];"]
        lines += [f"    c{i}[{j}] = ({x}[{j}] - {fmt(step.offset[j])}) / {fmt(step.gain[j])};"
                  for j in range(dim)]
        return lines, f"c{i}", dim
    if isinstance(step, Project):  # M > N: v = P u
        return [f"    {ctype} v[{plan.n}];", *_products("v", step.matrix, x, fmt)], "v", plan.n
    if isinstance(step, Couple):
        return _range_bits(plan, ctype, x) + _couple(plan, step, ctype, x, "g"), "g", plan.n
    if isinstance(step, Linear):  # f = C u
        bits = _range_bits(plan, ctype, x) if dim == plan.n else []
        return bits + [f"    {ctype} g[{plan.n}];", *_products("g", step.matrix, x, fmt)], "g", plan.n
    if isinstance(step, Rotate):  # sensor frame -> reference frame
        return [f"    {ctype} r[{plan.n}];", *_products("r", step.matrix, x, fmt)], "r", plan.n
    raise UnknownStep(step, "the C emitter")


def decouple_function(plan: ExportPlan, ctype: str) -> str:
    """The C function ``fsd_decouple`` (or ``_f``): the plan's steps in its order."""
    p, n = plan.prefix, plan.n
    fmt = numf if ctype == "float" else num
    name = f"{p}decouple_f(const float *u, float *f)" if ctype == "float" \
        else f"{p}decouple(const double *u, double *f)"
    lines = [f"uint32_t {name}", "{", "    uint32_t st = 0;"]
    for b, (lo, hi) in enumerate(plan.limits if ctype == "double" else plan.limits_f):
        if lo is not None:  # the raw channels, as passed in
            lines.append(f"    if (u[{b}] <= {fmt(lo)} || u[{b}] >= {fmt(hi)}) "
                         f"st |= (uint32_t)1 << {BIT_SATURATED};")
    finite = " || ".join(f"!isfinite(u[{b}])" for b in range(plan.m))
    lines.append(f"    if ({finite}) st |= (uint32_t)1 << {BIT_INPUT_NOT_FINITE};")
    x, dim = "u", plan.m
    for i, step in enumerate(plan.plan.steps):  # the plan's steps, in its order
        body, x, dim = _step(plan, step, ctype, x, dim, i)
        lines += body
    lines += [f"    f[{a}] = {x}[{a}];" for a in range(n)]
    # apply's not_finite: NaN, infinite, or beyond FORCE_LIMIT x the largest full scale
    bound = fmt(FORCE_LIMIT * max(abs(v) for v in plan.full_scale))
    ffinite = " || ".join(f"!({_fabs(ctype)}(f[{a}]) <= {bound})" for a in range(n))
    lines += [f"    if ({ffinite}) st |= (uint32_t)1 << {BIT_NOT_FINITE};", "    return st;", "}", ""]
    return "\n".join(lines)


def set_zero_function(plan: ExportPlan) -> str:
    """``set_zero(u)``: a raw zero reading (the inputs, its temperature among them) corrected
    to T0 as the plan's temperature step corrects a row, kept and subtracted from every
    row after (ATIDAQ's bias).  A ``zero: intercept`` model: ``set_zero(u)`` replaces the
    fitted offsets the header subtracts from raw outputs by default by the reading ``u``.
    '' for a model with neither."""
    step, p = plan.temperature, plan.prefix
    zero = plan.zero
    if step is None and zero is not None:
        m = len(zero.offset)
        values = ", ".join(num(v) for v in zero.offset)
        lines = [f"/* the model's fitted offsets (zero: intercept) until {p}set_zero */",
                 f"static double {p}zero[{m}] = {{{values}}};",
                 f"void {p}set_zero(const double *u)", "{", "    int j;",
                 f"    for (j = 0; j < {m}; ++j) {p}zero[j] = u[j];"]
        return "\n".join([*lines, "}", ""])
    if step is None:
        return ""
    c, dim = step.channel, step.n_inputs
    lines = [f"static double {p}zero_t0[{dim}];  /* 0 until {p}set_zero */",
             f"void {p}set_zero(const double *u)", "{",
             f"    const double dt = u[{c}] - {num(step.t0)};"]
    lines += [f"    {p}zero_t0[{j}] = (u[{j}] - {num(step.b[j])} * dt) / ({num(1.0)} + "
              f"{num(step.g[j])} * dt);" for j in range(dim)]
    return "\n".join([*lines, "}", ""])
