"""An interval on every decoupled force: conformal prediction on held-out residuals,
with a term for the model's error under combined loads.

``fit`` scores the model's method on calibration points it was not fitted on (the
held-out rounds of the verdict, :mod:`fsdecouple.evaluation.heldout`), each point
decoupled where the interval is centred (:func:`centre`).  Each residual r = F_hat - F
on component a becomes a normalised score |r| / sigma_a, and for a coverage P the
half-width on a log's row is q sigma'_a(row), q the ceil((n + 1) P)-th smallest of the
n scores: split conformal prediction (Vovk et al., *Algorithmic Learning in a Random
World*, 2005; normalised scores: Papadopoulos et al., 2008; Lei et al., JASA 2018), the
rounds' models standing in for the final one as in cross-conformal prediction.

sigma (a held-out point) and sigma' (a row of a tared log decoupled by the final
model) differ, and a variance model says by how much.  With s the noise of one
reading in the decoupled force (from the repetitions' scatter), m zero readings per
sweep (m = inf with ``zero: fit``), n repetitions (n_t in a round's training set):

* a zero-corrected reading carries its sweep's zero readings too: s^2 (1 + 1/m); a
  log's row, tared over many rows, s^2;
* the model's own error at one load (chi and slope estimated from noisy sweeps, a lag
  eq. (1) cannot represent) adds v s^2 on a held-out point, which loads one component.
  With zero rows its main part is known: every chi_ab inherits the mean of its n_t
  sweeps' zero readings (data/zero.py, ``fitted_offsets``), so v = 1 / (m n_t).  With
  offsets fitted (``zero: fit``, a lag) v is measured: the mean of r^2 / s^2 - (1 + 1/m)
  over every held-out point and component, less p = (1 + 1/m) / (2 n_t) (the same order
  as its own scatter: the rounds are three realisations of the model's error), and never
  below p.  Measured with zero rows too, on simulated sensors it scattered from sensor
  to sensor (0.17-0.63 at m = 1, n_t = 4) without following the final model's error on
  the log (correlation -0.37 over 55 sensors): the rounds' few realisations of the zero
  readings' mean are not the final model's one, and a large one widened every row;
* a combined load carries every loaded component's share at once (the coupling error
  model is additive, eq. 1, so are its errors): on a row with loads f_b the model adds
  v s^2 (n_t / n) sum_b min(1, |f_b| / L_b), L_b the smallest calibrated non-zero
  |load| of component b; n_t / n, the final model being fitted on all n repetitions.

So sigma^2 = s^2 (1 + 1/m + v) and sigma'^2 = s^2 + v s^2 (n_t / n) sum_b min(1, |f_b| /
L_b): the term grows with the loads and the number of components loaded.  Single-axis
points never show that sum; it is the assumption (errors of the loads add, independent)
on which the intervals hold under combined loads, and docs/certificate.md gives its
measured coverage.  The scores of all components are pooled (they are unit-free), so q
does not hang on one component's few hundred points.  With one repetition s is
unknown: each component keeps its own raw residuals (sigma = sigma' = 1).  A sweep's
zero-load points are its own reference (r = 0 by construction) and score nothing.

Under combined loads eq. (11) also errs in second order (each chi is read at an
output that carries the other components' coupling): the interval is centred on the
forces refined by ``EXTRA_STEPS`` more fixed-point steps (eqs. 5-6,
:mod:`fsdecouple.core.decouple`), so it is not symmetric about the row's force, which
stays eq. (11)'s.  The held-out points are decoupled the same way, so the scores
measure the centre's error and not eq. (11)'s second-order error, which on a strongly
coupled sensor (5 % F.S.) is several times the noise even on single-axis points.

The scores, s, v s^2 n_t / n (``load_variance``) and L_b (``first_step``) live in the
model file's ``report.certificate["interval"]``; :func:`check_interval_data` checks
them when they are used.  No conformal library is used: MAPIE and crepes refit an
estimator per fold through scikit-learn's API, where these residuals come from the
verdict's own rounds and the method is a sort and an index.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np

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
    load_variance).
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


def check_interval_data(cal: Any, labels) -> None:
    """Refuse interval data a fit cannot have written: the fields this module added
    (``load_variance``, ``first_step``, ``zero_variance``) must be finite, >= 0, > 0 and
    >= 0 respectively, and ``deviations`` finite and sorted."""
    def bad(what: str, value) -> InputError:
        return InputError(f"intervals: the model file's interval data are damaged ({what} is "
                          f"{value!r}, expected a finite number {'>= 0' if 'variance' in what else '> 0'}); "
                          "refit the model", argument="interval")

    def number(x) -> bool:
        return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)

    for axis in labels:
        c = cal["components"][axis]
        if "load_variance" in c and not (number(c["load_variance"]) and c["load_variance"] >= 0):
            raise bad(f"load_variance of {axis}", c["load_variance"])
    deviations = cal.get("deviations")
    if deviations is not None:
        if not (isinstance(deviations, list) and deviations and all(number(x) for x in deviations)
                and all(x <= y for x, y in zip(deviations[:-1], deviations[1:], strict=True))):
            raise InputError("intervals: the model file's interval data are damaged (deviations "
                             "are not finite numbers in ascending order); refit the model",
                             argument="interval")
        shares = cal.get("zero_variance")
        if not isinstance(shares, dict):
            raise bad("zero_variance", shares)
        for axis, value in shares.items():
            if axis not in labels or not (number(value) and value >= 0):
                raise bad(f"zero_variance of {axis}", value)
    steps = cal.get("first_step")
    if steps is not None:
        if not isinstance(steps, dict):
            raise bad("first_step", steps)
        for axis, value in steps.items():
            if axis not in labels or not (number(value) and value > 0):
                raise bad(f"first_step of {axis}", value)


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
        raise InputError("intervals: the model file has no held-out residuals to calibrate "
                         "intervals on (fitted by an older fsdecouple, or without the held-out "
                         "verdict); refit it", argument="interval")
    labels = model.layout.labels
    check_interval_data(cal, labels)
    at_rows = f is not None
    f = np.asarray(f, dtype=float) if at_rows else np.zeros((1, len(labels)))
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


def _convolved(cal: dict[str, Any], p: float, f: np.ndarray, labels) -> np.ndarray:
    """Half-widths, shape (n, N), from the within-sweep deviations z_i and a row's
    between-sweep share.

    A row's error is s z + g: z drawn from the held-out deviations (each reading's own
    error and the model's along a sweep), g ~ N(0, rho^2 s^2) the share a sweep of
    calibration points has in common, here the final model's inherited zero readings
    (rho^2 = sum_b c_b min(1, |f_b| / L_b), c_b = ``zero_variance``, :func:`row_sigma`).  The
    half-width h = s Q(rho) solves mean_i P(|z_i + g / s| <= Q) = P (n + 1) / n, the
    split-conformal correction; at rho = 0 it is the ceil((n + 1) P)-th smallest |z_i|.
    """
    z = np.asarray(cal["deviations"], dtype=float)
    shares = cal.get("zero_variance") or {}
    top = math.sqrt(sum(shares.get(a, 0.0) for a in labels if a in (cal.get("first_step") or {})))
    grid, q = _q_grid(z.tobytes(), p, top)
    sigma = np.array([cal["components"][a]["sigma"] for a in labels])
    rho = np.sqrt(np.maximum(row_sigma(cal, f, labels) ** 2 / sigma ** 2 - 1.0, 0.0))
    return sigma * np.interp(rho, grid, q)


@functools.lru_cache(maxsize=8)
def _q_grid(deviations: bytes, p: float, top: float) -> tuple[np.ndarray, np.ndarray]:
    """Q(rho) on ``GRID`` ratios from 0 to ``top`` (every ramp 1: the largest a row has),
    the same for every chunk of a log; solved once per model and P."""
    from scipy.special import ndtr

    z = np.frombuffer(deviations, dtype=float)
    n = z.size
    target = p * (n + 1) / n
    if target >= 1.0:
        raise InputError(f"coverage {p!r}: {n} held-out deviations calibrate intervals up to "
                         f"P = {n / (n + 1):.3f}", argument="interval")
    grid = np.linspace(0.0, top, GRID)
    q0 = np.sort(np.abs(z))[math.ceil((n + 1) * p) - 1]
    if not top > 0.0:
        return grid, np.full(GRID, q0)
    lo = np.zeros(GRID - 1)
    hi = np.full(GRID - 1, float(np.abs(z).max()) + 10.0 * top)
    r = grid[1:, None]
    for _ in range(50):  # bisection: the coverage rises with the half-width
        mid = 0.5 * (lo + hi)
        covered = np.mean(ndtr((mid[:, None] - z) / r) - ndtr((-mid[:, None] - z) / r), axis=1)
        lo, hi = np.where(covered < target, mid, lo), np.where(covered < target, hi, mid)
    q = np.concatenate(([q0], hi))
    return grid, q


def centre(model, u: np.ndarray, f: np.ndarray | None = None) -> np.ndarray:
    """Where an interval is centred: eq. (11)'s forces refined by ``EXTRA_STEPS`` more
    fixed-point steps (eqs. 5-6), shape (n, N) [load unit], without rotation.

    The held-out points are scored here too, so the scores measure the centre's error.
    A row whose refinement does not settle keeps eq. (11)'s force ``f`` (computed
    from ``u`` if not given).
    """
    if f is None:
        f = model.decouple(u, rotate=False)
    if getattr(model, "method", None) != "svr":  # the calibration matrix: nothing to refine
        return f
    with np.errstate(all="ignore"):
        refined = model.decouple(np.nan_to_num(u), rotate=False,
                                 refine=model.settings.refine + EXTRA_STEPS)
    return np.where(np.isfinite(refined), refined, f)


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
