"""An interval on every decoupled force: the held-out residuals' own part, measured,
with the part a sweep shares, modelled (issue 33).

``fit`` scores the model's method on calibration points it was not fitted on (the
held-out rounds of the verdict, :mod:`fsdecouple.evaluation.heldout`), each point
decoupled where the interval is centred (:func:`centre`).  s_a is the noise of one
reading in decoupled component a (from the repetitions' scatter).

Zero rows and one-way single-axis sweeps in two repetitions or more (an svr model of
N outputs): the least-squares model of the sweeps
(:mod:`fsdecouple.evaluation.sweep_model`) centres the interval and gives its error's
variance at the row, the reading's sigma_a^2 and the model's rho_a^2 sigma_a^2; the
half-width is sigma_a Q(rho_a), Q from the fits' studentised residuals as below
(:func:`_swept`).  The SVR's chi follow each step's mean (Table 2: epsilon = 1e-4),
and their error, fixed per sensor, was of unknown size: docs/design/intervals.md.

Otherwise, with zero rows.  A residual r = F_hat - F is split in two:

* what a sweep shares: its zero reading, and the round's model's inherited zero
  readings.  Every chi_ab (and omega_b) is fitted to the b sweeps less their zero
  readings, so the final model inherits their mean error, the same at every load: one
  realisation per calibration, of known variance s_a^2 mean_g(1/m_g) / G
  (:func:`fsdecouple.data.zero.mean_offset_variance`).  The rounds' realisations are
  not the final model's: held-out, they are set apart, each sweep's mean residual;
* what each point adds: the residuals less their sweep's mean, over s_a, pooled over
  the components (:func:`within_sweeps`), the deviations z_i.

On a log's row with loads f_b the shared part is a bias b, one value per calibration
(the same on every row), of variance rho^2 s_a^2, rho^2 = sum_b c_b min(1, |f_b| /
L_b) (L_b the smallest calibrated non-zero |load| of b: the first step, over which the
inherited error ramps in). With the centre's shift taken back, c_b is what the shift
leaves (:func:`fsdecouple.data.zero.shift_variance`), else that whole variance. The
half-width is s_a Q(rho), Q covering P (n + 1) / n of the deviations z_i shifted by
+-K rho, the bias a sensor exceeds with probability 1 - ``CONFIDENCE``
(:func:`_convolved`): P per sensor on 90 % of sensors, a tolerance interval (Wald,
*Ann. Math. Statist.* 1943; Vovk, "Conditional validity of inductive conformal
predictors", ACML 2012), not P on average over sensors. At rho = 0 it is the split-
conformal quantile of |z| (Vovk et al., *Algorithmic Learning in a Random World*,
2005; Lei et al., JASA 2018). It grows with the loads and the number of components
loaded.  The assumption: a row's error is a held-out point's within its sweep plus the
zero readings' mean error of every loaded component (errors of the loads add, eq. 1);
docs/certificate.md gives the measured coverage.

Offsets fitted (``zero: fit``, m = inf) or no sweeps to set apart: normalised scores
|r| / sigma_a, pooled, and a half-width q sigma'_a(row), q the ceil((n + 1) P)-th
smallest score.  With m zero readings per sweep, n repetitions (n_t in a round):
sigma^2 = s^2 (1 + 1/m + v) on a held-out point, sigma'^2 = s^2 + v s^2 (n_t / n)
sum_b min(1, |f_b| / L_b) on a tared row.  v is the model's share at one load: with
zero rows the zero readings' 1 / (m n_t); with offsets fitted (the log's error is then
mostly a lag's) measured, the mean of r^2 / s^2 - (1 + 1/m) over the held-out points
less p = (1 + 1/m) / (2 n_t) (its own scatter is of that order), never below p.
Measured with zero rows, v scattered 0.17-0.63 over simulated sensors without
following the final model's error (correlation -0.37 over 55): the reason for the
split above.  With one repetition s is unknown: each component keeps its own raw
residuals (sigma = sigma' = 1).  A sweep's zero-load points are its own reference
(r = 0 by construction) and score nothing.

The centre (:func:`centre`) is not the row's force, which stays eq. (11)'s: with the
sweep model, its forces (rows it does not settle, or settles beyond the calibrated
range: as below).  Otherwise, since under combined loads eq. (11) also errs in second
order (each chi is read at an output that carries the other components' coupling),
the forces refined by ``EXTRA_STEPS`` more fixed-point steps (eqs. 5-6,
:mod:`fsdecouple.core.decouple`); the held-out points are decoupled the same way.
With zero rows (and no sweep model) the final model's centre then takes back the zero
readings' mean error as the offsets fitted from all points estimate it
(``zero_shift``, :func:`shifted`); the estimate's own error is the bias the intervals
keep (c_b above).

The scores, s, ``load_variance`` (v s^2 n_t / n), ``first_step`` (L_b), ``deviations``,
``zero_variance`` (c_b), ``zero_shift`` and ``least_squares`` (the sweep model) live in the
model file's ``report.certificate["interval"]``;
:func:`check_interval_data` checks them when the model file loads
(:mod:`fsdecouple.core.modelfile`) and again when they are used.  No conformal library is
used: MAPIE and crepes refit an estimator per fold through scikit-learn's API, where
these residuals come from the verdict's own rounds and the method is a sort and an index.
"""

from __future__ import annotations

import functools
import math
from statistics import NormalDist
from typing import Any

import numpy as np

from ..core.interval_data import SweepModel, check_interval_data
from ..errors import InputError

EXTRA_STEPS = 3  # refinement steps that estimate eq. (11)'s second-order error


def interval_calibration(true: np.ndarray, predicted: np.ndarray, labels, noise=None,
                         zeros: float = 1.0, repetitions: int = 1,
                         trained: float = 1.0, sweeps=None, zero_variance=None) -> dict[str, Any]:
    """The conformal scores of held-out forces (``true``, ``predicted``: shape (n, N)
    [load unit]), and the variance model of a log's row.

    ``noise``: per component, s [load unit] (NaN: unknown); ``zeros``: m (inf: zero
    offsets fitted); ``repetitions``: n; ``trained``: n_t.  Returns ``{"scores": pooled
    sorted scores or None, "first_step": {axis: L_b [load unit]}, "components": {axis:
    {"sigma": s, "scores": own sorted scores or None, "load_variance": v s^2 n_t / n
    [load unit^2]}}}`` (a component without s: sigma 1, its own raw residuals, no
    load_variance).  ``sweeps``: each point's held-out sweep, and ``zero_variance``: c_b
    per component (zero rows, :func:`fsdecouple.data.zero.mean_offset_variance`); given
    both, the result adds ``"deviations"`` (sorted z_i) and ``"zero_variance"``
    ({axis: c_b}), which :func:`half_widths` then uses.
    """
    n_comp = len(labels)
    noise = np.full(n_comp, np.nan) if noise is None else np.asarray(noise, dtype=float)
    loaded = (true != 0.0).any(axis=1)  # a sweep's zero reading is its own reference: r = 0
    reading = 1.0 + 1.0 / zeros  # a held-out point's zero-corrected reading [s^2]
    known = [a for a in range(n_comp) if np.isfinite(noise[a]) and noise[a] > 0]
    residuals = [np.abs(predicted[:, a] - true[:, a]) for a in range(n_comp)]
    ok = [np.isfinite(predicted[:, a]) & loaded for a in range(n_comp)]
    v, out = 0.0, {}
    if known:
        excess = float(np.mean(np.concatenate(
            [(residuals[a][ok[a]] / noise[a]) ** 2 for a in known]))) - reading
        p = reading / (2.0 * trained)
        if sweeps is not None and zero_variance is not None:
            signed = [predicted[:, a] - true[:, a] for a in range(n_comp)]
            out["deviations"], _ = within_sweeps(signed, ok, noise, known, np.asarray(sweeps))
            out["zero_variance"] = {axis: float(c) for axis, c in zip(labels, zero_variance, strict=True)
                                    if np.isfinite(c)}
        # zero rows: the share is known, 1 / (m n_t); measured from a few rounds it
        # scattered more than it informed (docs/certificate.md, "The model's share")
        v = 1.0 / (zeros * trained) if math.isfinite(zeros) else max(p, excess - p)
    pooled, comps = [], {}
    for a, axis in enumerate(labels):
        r = residuals[a][ok[a]]
        if a in known:
            s = float(noise[a])
            pooled.append(r / (s * math.sqrt(reading + v)))
            comps[axis] = {"sigma": s, "scores": None,
                           "load_variance": v * s * s * trained / repetitions}
        else:
            comps[axis] = {"sigma": 1.0, "scores": np.sort(r).tolist()}
    steps = {}
    for b, axis in enumerate(labels):
        nonzero = np.abs(true[:, b])[true[:, b] != 0.0]
        if nonzero.size:
            steps[axis] = float(nonzero.min())
    return {"scores": np.sort(np.concatenate(pooled)).tolist() if pooled else None,
            "first_step": steps, "components": comps, **out}


def within_sweeps(residuals, ok, noise, known, sweeps: np.ndarray) -> tuple[list[float], float]:
    """The held-out residuals less their sweep's mean, over s, pooled and sorted; and the
    sweeps' mean squared mean residual beyond its own noise [s^2].

    A sweep's mean residual is the part a whole sweep shares (its zero reading, the
    round's model's inherited zero readings: the between-sweep share); what is left
    is each reading's own error, the model's shape error along the sweep and, on
    sweeps out and back, a lag's.  Scaled by sqrt(n_g / (n_g - 1)) for the mean's own
    share of the n_g points of sweep g; sweeps of one loaded point give none.
    """
    out, between = [], []
    for a in known:
        r, g = residuals[a][ok[a]] / noise[a], sweeps[ok[a]]
        _, idx, count = np.unique(g, return_inverse=True, return_counts=True)
        mean = np.bincount(idx, weights=r) / count
        several = count[idx] > 1
        w = (r - mean[idx]) * np.sqrt(count[idx] / np.maximum(count[idx] - 1, 1))
        out.append(w[several])
        within = np.bincount(idx, weights=w * w) / count  # each sweep's own noise
        between.append((mean ** 2 - within / count)[count > 1])
    return np.sort(np.concatenate(out)).tolist(), float(np.mean(np.concatenate(between)))


def row_sigma(cal: dict[str, Any], f: np.ndarray, labels) -> np.ndarray:
    """sigma' of every row and component, shape (n, N) [load unit], at forces ``f``
    (shape (n, N)): the reading's noise and, per loaded component b, one share of the
    model's error (models fitted before the share was stored: sigma' alone)."""
    steps = cal.get("first_step") or {}
    shares = cal.get("zero_variance")
    loads = np.zeros(len(f))
    for b, axis in enumerate(labels):
        if axis in steps:
            ramp = np.minimum(1.0, np.abs(np.nan_to_num(f[:, b])) / steps[axis])
            loads += ramp if shares is None else shares.get(axis, 0.0) * ramp
    out = np.empty((len(f), len(labels)))
    for a, axis in enumerate(labels):
        c = cal["components"][axis]
        share = c["sigma"] ** 2 * loads if shares is not None else c.get("load_variance", 0.0) * loads
        out[:, a] = np.sqrt(c["sigma"] ** 2 + share)
    return out


def check_coverage(p: Any) -> float:
    """``--interval P``: a coverage probability strictly between 0 and 1."""
    if isinstance(p, bool) or not isinstance(p, int | float) or not 0.0 < p < 1.0:
        raise InputError(f"coverage {p!r}: expected a probability between 0 and 1, e.g. 0.95",
                         argument="interval")
    return float(p)


def interval_names(loads) -> tuple[str, ...]:
    """The added columns: ``fx_lo, fx_hi, fy_lo, ...``."""
    return tuple(f"{c}_{end}" for c in loads for end in ("lo", "hi"))


def _quantile(scores: list[float], p: float, axis: str) -> float:
    k = math.ceil((len(scores) + 1) * p)
    if k > len(scores):
        raise InputError(f"coverage {p!r}: {len(scores)} held-out points of {axis} calibrate "
                         f"intervals up to P = {len(scores) / (len(scores) + 1):.3f}",
                         argument="interval")
    return float(scores[k - 1])


def half_widths(model, p: float, f: np.ndarray | None = None) -> np.ndarray:
    """Half-widths of the P intervals [the model's load unit]: shape (N,) at zero load, or
    (n, N) at the rows of forces ``f`` (shape (n, N))."""
    p = check_coverage(p)
    cert = (model.report.certificate if model.report is not None else None) or {}
    cal = cert.get("interval")
    if not cal and model.layout.overdetermined:
        raise InputError(f"intervals: not supported for a model of more outputs than components "
                         f"({model.layout.m} for {model.n_components}, M > N): fit keeps no "
                         "held-out residuals for it; decouple without intervals",
                         argument="interval")
    if not cal:
        from ..core.modelfile import why_no_certificate

        raise InputError("intervals: the model file has no held-out residuals to calibrate "
                         f"intervals on ({why_no_certificate(model)})", argument="interval")
    labels = model.layout.labels
    check_interval_data(cal, labels)
    at_rows = f is not None
    f = np.asarray(f, dtype=float) if at_rows else np.zeros((1, len(labels)))
    if cal.get("least_squares") is not None:
        out = _swept(cal, p, f)
        return out if at_rows else out[0]
    if cal.get("deviations") is not None:
        out = _convolved(cal, p, f, labels)
        return out if at_rows else out[0]
    q = np.empty(len(labels))
    for a, axis in enumerate(labels):
        c = cal["components"][axis]
        q[a] = _quantile(c["scores"] if c["scores"] is not None else cal["scores"], p, axis)
    out = q * row_sigma(cal, f, labels)
    return out if at_rows else out[0]


GRID = 33  # between-sweep ratios rho at which the half-width is solved, then interpolated
CONFIDENCE = 0.9  # of a sensor: its shared error lies within K rho (the interval's width)
K = NormalDist().inv_cdf((1.0 + CONFIDENCE) / 2.0)  # two-sided normal quantile of CONFIDENCE


def _convolved(cal: dict[str, Any], p: float, f: np.ndarray, labels) -> np.ndarray:
    """Half-widths, shape (n, N), from the within-sweep deviations z_i and a row's
    between-sweep share.

    A row's error is s z + b: z drawn from the held-out deviations (each reading's own
    error and the model's along a sweep), b the share a sweep of calibration points has
    in common, here what the final model's inherited zero readings leave once the
    centre takes back their estimate: one value per calibration, the same on every row
    of a log, of variance rho^2 s^2 (rho^2 = sum_b c_b min(1, |f_b| / L_b), c_b =
    ``zero_variance``, :func:`row_sigma`).  Per sensor, not on average over sensors: the
    half-width h = s Q(rho) covers P (n + 1) / n of the deviations shifted by b = +-K rho,
    a bias a sensor exceeds with probability 1 - ``CONFIDENCE`` (a tolerance interval of
    content P and confidence 0.9 in b); at rho = 0 it is the ceil((n + 1) P)-th smallest
    |z_i|, the split-conformal quantile.
    """
    z = np.asarray(cal["deviations"], dtype=float)
    shares = cal.get("zero_variance") or {}
    top = math.sqrt(sum(shares.get(a, 0.0) for a in labels if a in (cal.get("first_step") or {})))
    grid, q = _q_grid(z.tobytes(), p, top)
    sigma = np.array([cal["components"][a]["sigma"] for a in labels])
    rho = np.sqrt(np.maximum(row_sigma(cal, f, labels) ** 2 / sigma ** 2 - 1.0, 0.0))
    return sigma * np.interp(rho, grid, q)


def _swept(cal: dict[str, Any], p: float, f: np.ndarray) -> np.ndarray:
    """Half-widths, shape (n, N), about the least-squares sweep model's forces ``f``:
    s_a Q(rho_a), s_a^2 the reading's variance in force a at the row and rho_a^2 the
    model's over it (:meth:`fsdecouple.core.interval_data.SweepModel.variances`),
    Q as :func:`_convolved`'s with the model's studentised residuals as the deviations
    and its error at the row as the bias.  Q is solved on a grid up to the model's
    largest rho in its calibrated range (the same for every block of a log) and
    interpolated; beyond it, where the model extrapolates, it grows by K per unit of
    rho, as Q does for large rho (Q - K rho falls towards a quantile of the deviations:
    the line is above Q).  NaN where the model's Jacobian is singular."""
    model = SweepModel(cal["least_squares"])
    reading, shared = model.variances(f)
    with np.errstate(all="ignore"):
        rho = np.sqrt(shared / reading)
    top = max(model.largest_ratio(), 0.125)
    grid, q = _q_grid(np.asarray(cal["deviations"], dtype=float).tobytes(), p, top)
    out = np.interp(rho, grid, q)
    beyond = rho > top
    out[beyond] = q[-1] + K * (rho[beyond] - top)
    return np.sqrt(reading) * out


@functools.lru_cache(maxsize=8)
def _q_grid(deviations: bytes, p: float, top: float) -> tuple[np.ndarray, np.ndarray]:
    """Q(rho) on ``GRID`` ratios from 0 to ``top`` (every ramp 1: the largest a row has),
    the same for every chunk of a log; solved once per model and P.

    At bias b = K rho the share of the deviations covered, (#{|z_i + b| <= Q} +
    #{|z_i - b| <= Q}) / 2n, reaches the target at the ceil(2 n target)-th smallest of
    the 2n values |z_i +- b| (b's sign is unknown: both count alike).
    """
    z = np.frombuffer(deviations, dtype=float)
    n = z.size
    target = p * (n + 1) / n
    if target >= 1.0:
        raise InputError(f"coverage {p!r}: {n} held-out deviations calibrate intervals up to "
                         f"P = {n / (n + 1):.3f}", argument="interval")
    grid = np.linspace(0.0, top, GRID)
    b = K * grid[:, None]
    both = np.sort(np.concatenate([np.abs(z + b), np.abs(z - b)], axis=1), axis=1)
    q = both[:, math.ceil(2 * n * target) - 1]
    q[0] = np.sort(np.abs(z))[math.ceil((n + 1) * p) - 1]  # b = 0: the conformal quantile
    return grid, q


def centre(model, u: np.ndarray, f: np.ndarray | None = None) -> np.ndarray:
    """Where an interval is centred, shape (n, N) [load unit], without rotation: the
    least-squares sweep model's forces where the model file has it
    (:mod:`fsdecouple.evaluation.sweep_model`, from eq. (11)'s forces ``f``), else
    eq. (11)'s forces refined by ``EXTRA_STEPS`` more fixed-point steps (eqs. 5-6).

    The held-out points are scored here too, so the scores measure the centre's error.
    A row whose refinement does not settle keeps eq. (11)'s force ``f`` (computed
    from ``u`` if not given), a row the sweep model does not settle the refined one.
    Without the sweep model, a final model fitted on zero rows then takes back the
    error its chi and omega inherited from them, as the offsets fitted from all points
    estimate it (``zero_shift``, :func:`shifted`); the held-out rounds' models have none.
    """
    if f is None:
        f = model.decouple(u, rotate=False)
    if getattr(model, "method", None) != "svr":  # the calibration matrix: nothing to refine
        return f
    cert = (model.report.certificate if getattr(model, "report", None) is not None else None) or {}
    cal = cert.get("interval") or {}
    u = np.asarray(u, dtype=float)
    if cal.get("least_squares"):
        sweep_model = SweepModel(cal["least_squares"])
        swept = sweep_model.forces(u, f)
        left = np.flatnonzero(~(np.isfinite(swept).all(axis=1) & sweep_model.inside(swept)))
        if left.size:
            swept[left] = _refined(model, u[left], f[left])
        return swept
    mid = _refined(model, u, f)
    return shifted(cal, mid, model.layout.labels) if cal.get("zero_shift") else mid


def _refined(model, u: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Eq. (11)'s forces ``f`` refined by ``EXTRA_STEPS`` more steps; ``f`` where that
    does not settle."""
    with np.errstate(all="ignore"):
        refined = model.decouple(np.nan_to_num(u), rotate=False,
                                 refine=model.settings.refine + EXTRA_STEPS)
    return np.where(np.isfinite(refined), refined, f)


def shifted(cal: dict[str, Any], f: np.ndarray, labels) -> np.ndarray:
    """``f`` less the zero rows' inherited error at ``f``: per loaded component b, each
    component a != b moves by zero_shift[b][a] min(1, |f_b| / L_b) (chi_ab's share, ramped
    in over the first step as the chi is), and b by zero_shift[b][b] f_b (omega_b's
    slope) [load unit]."""
    out = np.array(f, dtype=float, copy=True)
    steps = cal.get("first_step") or {}
    for b, axis in enumerate(labels):
        row = cal["zero_shift"].get(axis)
        if row is None or axis not in steps:
            continue
        fb = np.nan_to_num(f[:, b])
        ramp = np.minimum(1.0, np.abs(fb) / steps[axis])
        for a in range(len(labels)):
            out[:, a] += row[a] * (fb if a == b else ramp)
    return out


def with_intervals(model, f: np.ndarray, p: float, u: np.ndarray | None = None) -> np.ndarray:
    """``f`` followed by each component's lower and upper bound, shape (n, 3N).

    ``f``: forces decoupled without rotation from the zero-corrected outputs ``u``
    (None: the intervals are centred on ``f``).
    """
    if model.rotation is not None:
        raise InputError("intervals: they are calibrated in the sensor's frame; this model "
                         "rotates its forces (rotation or frame in its config)", argument="interval")
    mid = f if u is None else centre(model, u, f)
    h = half_widths(model, p, mid)
    bounds = np.stack([mid - h, mid + h], axis=2).reshape(len(f), -1)
    return np.hstack([f, bounds])
