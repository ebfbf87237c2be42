"""An interval on every decoupled force: conformal prediction on held-out residuals.

``fit`` scores the model's method on calibration points it was not fitted on (the
held-out rounds of the verdict, :mod:`fsdecouple.evaluation.heldout`).  Each point's
residual r = F_hat - F on component a becomes a normalised score s = |r| / sigma_a,
and for a coverage P the half-width on a log's row is q sigma'_a, q the
ceil((n + 1) P)-th smallest of the n scores: split conformal prediction (Vovk et al.,
*Algorithmic Learning in a Random World*, 2005; normalised scores: Papadopoulos et al.,
2008; Lei et al., JASA 2018), the rounds' models standing in for the final one as in
cross-conformal prediction.

sigma (a held-out point) and sigma' (a row of a tared log decoupled by the final
model) differ, and a noise model says by how much.  With s the noise of one reading
in the decoupled force (from the repetitions' scatter), m zero readings per sweep, N
components and n repetitions (n_t in a round's training set):

* a zero-corrected reading carries its sweep's zero readings too: s^2 (1 + 1/m); a
  log's row, tared over many rows, s^2;
* eq. (11) has N estimated terms (the slope and N - 1 chi) of output a, each from n
  repetitions of such readings: N s^2 (1 + 1/m) / n (n_t for a round's model);

so sigma^2 = s^2 (1 + 1/m) (1 + N / n_t) and sigma'^2 = s^2 (1 + N (1 + 1/m) / n).  What
the noise model misses (the SVR's own error, a sensor that is not the paper's) stays
in the scores and widens q.  The scores of all components are pooled (they are
unit-free), so q does not hang on one component's few hundred points.  With one
repetition s is unknown: each component keeps its own raw residuals (sigma = sigma' = 1).

Under combined loads eq. (11) also errs in second order (each chi is read at an
output that carries the other components' coupling; single-axis points never show
it): the interval is centred on the forces refined by ``EXTRA_STEPS`` more
fixed-point steps (eqs. 5-6, :mod:`fsdecouple.core.decouple`), so it is not symmetric
about the row's force, which stays eq. (11)'s.

The scores and sigma' live in the model file's ``report.certificate["interval"]``.
No conformal library is used: MAPIE and crepes refit an estimator per fold through
scikit-learn's API, where these residuals come from the verdict's own rounds and the
method is a sort and an index.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import InputError

EXTRA_STEPS = 3  # refinement steps that estimate eq. (11)'s second-order error


def interval_calibration(true: np.ndarray, predicted: np.ndarray, labels, noise=None,
                         zeros: float = 1.0, repetitions: int = 1,
                         trained: float = 1.0) -> dict[str, Any]:
    """The conformal scores of held-out forces (``true``, ``predicted``: shape (n, N)).

    ``noise``: per component, s [load unit] (NaN: unknown); ``zeros``: m;
    ``repetitions``: n; ``trained``: n_t.  Returns ``{"scores": pooled sorted scores
    or None, "components": {axis: {"sigma": sigma', "scores": own sorted scores or None}}}``.
    """
    n_comp = len(labels)
    noise = np.full(n_comp, np.nan) if noise is None else np.asarray(noise, dtype=float)
    pooled, comps = [], {}
    for a, axis in enumerate(labels):
        ok = np.isfinite(predicted[:, a])
        r = np.abs(predicted[ok, a] - true[ok, a])
        s = float(noise[a])
        if np.isfinite(s) and s > 0:
            held = s * np.sqrt((1.0 + 1.0 / zeros) * (1.0 + n_comp / trained))
            row = s * np.sqrt(1.0 + n_comp * (1.0 + 1.0 / zeros) / repetitions)
            pooled.append(r / held)
            comps[axis] = {"sigma": row, "scores": None}
        else:
            comps[axis] = {"sigma": 1.0, "scores": np.sort(r).tolist()}
    return {"scores": np.sort(np.concatenate(pooled)).tolist() if pooled else None,
            "components": comps}


def check_coverage(p: Any) -> float:
    """``--interval P``: a coverage probability strictly between 0 and 1."""
    if isinstance(p, bool) or not isinstance(p, int | float) or not 0.0 < p < 1.0:
        raise InputError(f"--interval {p!r}: expected the coverage as a probability between 0 "
                         "and 1, e.g. 0.95")
    return float(p)


def interval_names(loads) -> tuple[str, ...]:
    """The added columns: ``fx_lo, fx_hi, fy_lo, ...``."""
    return tuple(f"{c}_{end}" for c in loads for end in ("lo", "hi"))


def _quantile(scores: list[float], p: float, axis: str) -> float:
    k = math.ceil((len(scores) + 1) * p)
    if k > len(scores):
        raise InputError(f"--interval {p!r}: {len(scores)} held-out points of {axis} calibrate "
                         f"intervals up to P = {len(scores) / (len(scores) + 1):.3f}")
    return float(scores[k - 1])


def half_widths(model, p: float) -> np.ndarray:
    """Half-width per component, shape (N,), of the P intervals [the model's load unit]."""
    p = check_coverage(p)
    cert = (model.report.certificate if model.report is not None else None) or {}
    cal = cert.get("interval")
    if not cal and model.layout.overdetermined:
        raise InputError(f"--interval: not supported for a model of more outputs than components "
                         f"({model.layout.m} for {model.n_components}, M > N): fit keeps no "
                         "held-out residuals for it; decouple without --interval")
    if not cal:
        raise InputError("--interval: the model file has no held-out residuals to calibrate "
                         "intervals on (fitted by an older fsdecouple, or with --no-verdict); "
                         "refit it")
    out = np.empty(model.n_components)
    for a, axis in enumerate(model.layout.labels):
        c = cal["components"][axis]
        scores = c["scores"] if c["scores"] is not None else cal["scores"]
        out[a] = _quantile(scores, p, axis) * c["sigma"]
    return out


def with_intervals(model, f: np.ndarray, p: float, u: np.ndarray | None = None) -> np.ndarray:
    """``f`` followed by each component's lower and upper bound, shape (n, 3N).

    ``f``: forces decoupled without rotation from the zero-corrected outputs ``u``
    (None: the intervals are centred on ``f``).
    """
    if model.rotation is not None:
        raise InputError("--interval: the intervals are calibrated in the sensor's frame; this "
                         "model rotates its forces (rotation or frame in its config)")
    h = half_widths(model, p)
    centre = f
    if u is not None and model.method == "svr":
        with np.errstate(all="ignore"):
            refined = model.decouple(np.nan_to_num(u), rotate=False,
                                     refine=model.settings.refine + EXTRA_STEPS)
        centre = np.where(np.isfinite(refined), refined, f)  # a row refinement did not settle
    bounds = np.stack([centre - h, centre + h], axis=2).reshape(len(f), -1)
    return np.hstack([f, bounds])
