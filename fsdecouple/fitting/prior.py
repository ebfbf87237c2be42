"""In-situ recalibration toward a previous model (issue 32 item 7): ``fit NEW --prior OLD.json``.

A sensor recalibrated in place (a few poses on the robot it is mounted on) has too few
points for a fresh fit, and its old model has drifted.  robotology's in-situ calibration
fits the new matrix by ridge regression toward the previous one,

    C = argmin ||F - C U||^2 + lambda ||C - C_old||^2.

For M > N outputs (fitting/gauges.py) the old model is eq. (11) on v = P u: its omega
(k = 1) and chi act on v, and P is its matrix.  The ridge moves only what drift moves,
P and the zero, and keeps the old omega and chi, which a few poses cannot re-learn (they
hold the nonlinearity of the whole old calibration):

    v' = (I + D) P diag(1 + alpha) u + c,     f = eq. (11) of the old model at v',

alpha (M) each output's gain change (a gauge's drift), D (N x N) a linear change of the
loads v in full-scale units (a change of coupling), c (N) the offset [F.S.].  They are
fitted to the new rows by Gauss-Newton (the Jacobian of eq. (11) by central
differences) with the ridge penalty lambda_gain |alpha|^2 + lambda_load |D|^2; lambda
= inf fixes a part at the old model's, and c is free only where the new set has no zero
row (``zero: intercept``).  The result is the old model with P' = (I + D) P diag(1 +
alpha) and its zero moved by c: the same chi, exactly.

Both lambdas are chosen from :data:`LAMBDAS` by held-out error (leave one row out, or
:data:`FOLDS` folds of more rows), each scored by the held-out rows' worst component's
RMS error [F.S.], against a fresh fit of the new rows scored on the same folds: the
fresh fit is kept where it measured better.  A model with one output per component (no
P) shrinks by *prior rows* instead: lambda copies of the new rows loaded with what the
old model decodes from them join the fit (:func:`with_prior`), lambda from
:data:`COPIES`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pandas as pd

from ..core.metrics import interference_errors
from ..core.model import CouplingErrorModel, FitReport
from ..errors import InputError

# ridge weights per unit of the mean squared held-out residual [F.S.^2] (inf: that part
# stays the old model's); a 3 % drift costs about 1e-3 of residual, so the grid brackets it
LAMBDAS = (0.0, 1e-4, 1e-3, 1e-2, 1e-1, 1.0, math.inf)
COPIES = (0, 1, 2, 4)  # prior rows per new row (one output per component): 0 a fresh fit
FOLDS = 10  # held-out folds; fewer rows: leave one out
STEPS = 8  # Gauss-Newton steps of a correction (eq. (11) is nearly linear in v)
FRESH = "fresh fit"


@dataclass(frozen=True)
class Correction:
    """The change of an M > N model's matrix and zero (module docstring)."""

    alpha: np.ndarray  # (M,) each output's gain change
    d: np.ndarray  # (N, N) linear change of the loads v, in full-scale units
    c: np.ndarray  # (N,) offset of v [F.S.]

    def projection(self, p: np.ndarray, fs: np.ndarray) -> np.ndarray:
        """P' = (I + D) P diag(1 + alpha), D taken from full-scale to load units."""
        d = fs[:, None] * self.d / fs[None, :]
        return (np.eye(len(fs)) + d) @ p * (1.0 + self.alpha)


@dataclass(frozen=True)
class PriorChoice:
    """The candidate chosen and each one's held-out worst component's RMS error [F.S.]."""

    source: str
    best: str
    scores: dict[str, float]
    lambdas: tuple[float, float] | None = None  # (lambda_gain, lambda_load) of a correction
    copies: int = 0  # prior rows per new row (one output per component)

    @property
    def fresh(self) -> bool:
        return self.best == FRESH or (self.lambdas is None and self.copies == 0)

    def line(self) -> str:
        ranked = sorted(self.scores.items(), key=lambda kv: kv[1])
        shown = "; ".join(f"{k}: {100 * s:.3g} %" for k, s in ranked[:4])
        if self.best != FRESH and FRESH in self.scores and all(k != FRESH for k, _ in ranked[:4]):
            shown += f"; {FRESH}: {100 * self.scores[FRESH]:.3g} %"
        what = ("a fresh fit of the new rows" if self.fresh else
                f"the previous model with its matrix and zero corrected, {self.best}"
                if self.lambdas is not None else f"{self.best}")
        return (f"prior model {self.source}: {what}, chosen by held-out worst component's RMS "
                f"error over {len(self.scores)} candidates (best: {shown} F.S.)")


def check_prior(old, settings, source: str) -> None:
    """The old model must decode the same outputs into the same loads, in the same units."""
    if old.layout != settings.layout or old.settings.units != settings.units:
        raise InputError(f"prior model {source}: the model's outputs and loads "
                         f"({', '.join(old.layout.outputs)} -> {', '.join(old.layout.loads)}, "
                         f"{old.settings.output_unit} -> {old.settings.load_unit}) are not the "
                         "config's; a prior must be a model of the same sensor and layout",
                         argument="prior")


def check_prior_options(method: str | None, tune: bool, settings) -> str | None:
    """``--prior`` keeps the old chi or refits fresh ones as the held-out error says:
    neither tuning nor another method asked for on the command line would be obeyed on the
    first, so both are refused.  A config's ``method:`` other than svr (``init`` writes
    ``auto`` for poses) is not used either: the returned note says so."""
    if tune or method not in (None, "svr"):
        asked = "tuning the SVR settings" if tune else f"the method {method}"
        raise InputError(f"it chooses between the previous model, corrected, and a fresh fit "
                         f"by held-out error, and cannot take {asked} as well: fit without a "
                         "prior for that", argument="prior")
    if method is None and settings.method not in (None, "svr"):
        return (f"config method: {settings.method} not used: with a prior, fit chooses between "
                "the previous model, corrected, and a fresh svr fit by held-out error")
    return None


def correctable(old) -> bool:
    """An M > N coupling error model (a matrix P before eq. (11)) without temperature terms."""
    return (getattr(old, "projection", None) is not None and old.method == "svr"
            and old.temperature is None)


def _decoder(old, exact: bool = False):
    """g(v): the old model's eq. (11) at loads v (n, N), through outputs u = P^+ v (P P^+ = I);
    by its surrogate tables (as it decouples) unless ``exact``."""
    lift = np.linalg.pinv(old.projection)

    def g(v: np.ndarray) -> np.ndarray:
        return old.decouple(v @ lift.T, rotate=False, exact=exact)
    return g


def _central(g, x: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """dg/dx at each row of ``x`` (n, K), (n, N, K), by central differences of ``steps`` (K,)."""
    cols = []
    for b, h in enumerate(steps):
        step = np.zeros(len(steps))
        step[b] = h
        cols.append((g(x + step) - g(x - step)) / (2 * h))
    return np.stack(cols, axis=-1)


def _jacobian(g, v: np.ndarray, fs: np.ndarray) -> np.ndarray:
    """d(f / fs) / d(v / fs) of eq. (11) at each row, (n, N, N), by central differences."""
    return _central(g, v, 1e-4 * fs) * fs[None, None, :] / fs[None, :, None]


def fit_correction(u: np.ndarray, f: np.ndarray, g, p: np.ndarray, fs: np.ndarray,
                   jac: np.ndarray, lam_gain: float, lam_load: float,
                   intercept: bool) -> Correction:
    """The ridge fit of alpha, D, c (module docstring) to outputs u (n, M) and loads f (n, N).

    ``jac``: eq. (11)'s Jacobian at each row (:func:`_jacobian`).
    """
    alpha, d, c = fit_corrections(u, f, g, p, fs, jac, np.ones((1, len(u))),
                                  np.array([lam_gain]), np.array([lam_load]), intercept)
    return Correction(alpha[0], d[0], c[0])


def _predict(u, g, pn, fs, alpha, d, c) -> tuple[np.ndarray, np.ndarray]:
    """(w, f): each problem's P diag(1 + alpha) u [F.S.] and eq. (11) at its v', (B, n, N)."""
    w = np.einsum("bim,am->bia", u[None] * (1.0 + alpha[:, None, :]), pn)
    v = w + np.einsum("bac,bic->bia", d, w) + c[:, None, :]
    big_b, n, big_n = v.shape
    return w, g((v * fs).reshape(-1, big_n)).reshape(big_b, n, big_n)


def fit_corrections(u: np.ndarray, f: np.ndarray, g, p: np.ndarray, fs: np.ndarray,
                    jac: np.ndarray, weights: np.ndarray, lam_gain: np.ndarray,
                    lam_load: np.ndarray, intercept: bool):
    """B ridge fits at once (one evaluation of eq. (11) per step for all): problem b weighs
    row i by ``weights[b, i]`` (0: held out) with the penalties ``lam_gain[b]``,
    ``lam_load[b]`` (inf: that part fixed at 0).  Returns alpha (B, M), D (B, N, N), c (B, N).

    Gauss-Newton with eq. (11)'s Jacobian ``jac`` (n, N, N) at each row held fixed: each
    step evaluates eq. (11) itself, so only the step's direction is approximate.
    """
    n, m = u.shape
    big_n = len(fs)
    big_b = len(weights)
    k = m + big_n * big_n + big_n
    pn = p / fs[:, None]  # P into full-scale units
    alpha, d, c = np.zeros((big_b, m)), np.zeros((big_b, big_n, big_n)), np.zeros((big_b, big_n))
    lams = np.column_stack([np.repeat(lam_gain, m).reshape(big_b, m),
                            np.repeat(lam_load, big_n * big_n).reshape(big_b, -1),
                            np.zeros((big_b, big_n)) if intercept else np.full((big_b, big_n),
                                                                               math.inf)])
    free = np.isfinite(lams)
    pen = np.where(free, lams, 1.0)  # a fixed parameter: no Jacobian column, no gradient
    sw = np.sqrt(weights / weights.sum(axis=1, keepdims=True))[:, :, None]  # (B, n, 1)
    eye = np.eye(big_n)
    for _ in range(STEPS):
        w, pred = _predict(u, g, pn, fs, alpha, d, c)
        r = (pred - f) / fs * sw
        jv = np.zeros((big_b, n, big_n, k))
        jv[..., :m] = u[None, :, None, :] * ((eye + d) @ pn)[:, None]  # dv/dalpha
        for a in range(big_n):  # dv_a/dD_ab = w_b
            jv[:, :, a, m + a * big_n:m + (a + 1) * big_n] = w
        jv[..., m + big_n * big_n:] = eye  # dv/dc
        jv *= free[:, None, None, :]
        # batched matrix products (BLAS), not einsum's loops: 2-5x less CPU on a pose set
        jr = (jac[None] @ jv) * sw[..., None]  # (B, n, N, k)
        jr = jr.reshape(big_b, n * big_n, k)
        jrt = jr.transpose(0, 2, 1)
        theta = np.concatenate([alpha, d.reshape(big_b, -1), c], axis=1)
        h = jrt @ jr + pen[:, :, None] * np.eye(k)
        h += 1e-12 * np.eye(k)  # alpha and D overlap: a direction neither sees stays put
        grad = (jrt @ r.reshape(big_b, -1, 1))[..., 0] + pen * theta
        step = -np.linalg.solve(h, grad[..., None])[..., 0] * free
        step[~np.isfinite(step).all(axis=1)] = 0.0
        theta = theta + step
        alpha, d, c = (theta[:, :m], theta[:, m:m + big_n * big_n].reshape(big_b, big_n, big_n),
                       theta[:, m + big_n * big_n:])
        if np.abs(step).max() < 1e-9:
            break
    return alpha, d, c


def _folds(n: int, folds: int) -> list[np.ndarray]:
    """Held-out masks: leave one row out for n <= folds, else ``folds`` interleaved folds."""
    k = min(n, folds)
    order = np.random.default_rng(0).permutation(n)
    out = []
    for i in range(k):
        test = np.zeros(n, dtype=bool)
        test[order[i::k]] = True
        out.append(test)
    return out


def _worst(e: np.ndarray, fs: np.ndarray) -> float:
    return float((np.sqrt((e ** 2).mean(axis=0)) / fs).max())


def _label(lam_gain: float, lam_load: float) -> str:
    return f"lambda_gain = {lam_gain:g}, lambda_load = {lam_load:g}"


def choose_prior(calib, settings, old, source: str, *, folds: int = FOLDS,
                 workers: int | None = None, lambdas=LAMBDAS, copies=COPIES) -> PriorChoice:
    """The candidate of least held-out error: a corrected old model (one per pair of lambdas)
    or a fresh fit; for a model without P, lambda prior rows per new row (0: fresh)."""
    from .fit import fit

    check_prior(old, settings, source)
    n = len(calib.points)
    if n < 3:
        raise InputError(f"prior model {source}: {n} calibration rows; choosing lambda needs at "
                         "least 3 (each held out in turn)", argument="prior")
    layout = calib.layout
    outputs, loads = list(layout.outputs), list(layout.loads)
    fs = np.asarray(settings.full_scale, dtype=float)
    masks = _folds(n, folds)
    u, f = calib.voltages, calib.forces
    scores: dict[str, float] = {}

    def fresh_score(lam: int) -> float | None:
        errors = []
        for test in masks:
            train = with_prior(calib.select(~test), old, lam, source)
            try:
                model = fit(train, settings, workers=workers, tables=False)
            except InputError:
                return None  # too few rows left to fit without the prior
            held = calib.points[test]
            delta = (train.offsets[outputs].to_numpy(dtype=float)
                     - calib.offsets[outputs].to_numpy(dtype=float)).mean(axis=0)
            pred = model.decouple(held[outputs].to_numpy(dtype=float) - delta, rotate=False,
                                  exact=True)
            errors.append(pred - held[loads].to_numpy(dtype=float))
        return _worst(np.concatenate(errors), fs)

    if not correctable(old):
        labels = {FRESH if lam == 0 else f"lambda = {lam} prior rows per new row": lam
                  for lam in copies}
        for label, lam in labels.items():
            s = fresh_score(lam)
            if s is not None:
                scores[label] = s
        if not scores:
            raise InputError(f"prior model {source}: no lambda could be scored held out",
                             argument="prior")
        best = min(scores, key=lambda k: (scores[k], k != FRESH))
        lam = labels[best]
        return PriorChoice(str(Path(source)), best, scores, copies=lam)

    g = _decoder(old)
    p = np.asarray(old.projection, dtype=float)
    jac = _jacobian(_decoder(old, exact=True), u @ p.T, fs)  # tables are piecewise
    intercept = calib.zero == "intercept"
    pairs = [(a, b) for a in lambdas for b in lambdas]
    weights = np.array([~test for _ in pairs for test in masks], dtype=float)
    lam_gain = np.array([a for a, _ in pairs for _ in masks])
    lam_load = np.array([b for _, b in pairs for _ in masks])
    alpha, d, c = fit_corrections(u, f, g, p, fs, jac, weights, lam_gain, lam_load, intercept)
    _, pred = _predict(u, g, p / fs[:, None], fs, alpha, d, c)
    held = weights == 0
    for j, pair in enumerate(pairs):
        e = [pred[j * len(masks) + i][held[j * len(masks) + i]] - f[held[j * len(masks) + i]]
             for i in range(len(masks))]
        e = np.concatenate(e)
        if np.isfinite(e).all():
            scores[_label(*pair)] = _worst(e, fs)
    fresh = fresh_score(0)
    if fresh is not None:
        scores[FRESH] = fresh
    if not scores:
        raise InputError(f"prior model {source}: no lambda could be scored held out",
                         argument="prior")
    # ties go to the fresh fit, then to the larger lambdas (the smaller change)
    order = {_label(*pair): (-pair[0], -pair[1]) for pair in pairs}
    best = min(scores, key=lambda k: (scores[k], k != FRESH, order.get(k, (0, 0))))
    chosen = None if best == FRESH else next(pr for pr in pairs if _label(*pr) == best)
    return PriorChoice(str(Path(source)), best, scores, lambdas=chosen)


def corrected_model(calib, settings, old, choice: PriorChoice) -> CouplingErrorModel:
    """The old model with the correction of ``choice.lambdas`` fitted to all of ``calib``."""
    from .fit import fitted_zero, provenance
    from .linear import fit_calibration_matrix

    layout = settings.layout
    fs = np.asarray(settings.full_scale, dtype=float)
    u, f = calib.voltages, calib.forces
    p = np.asarray(old.projection, dtype=float)
    g = _decoder(old)
    intercept = calib.zero == "intercept"
    jac = _jacobian(_decoder(old, exact=True), u @ p.T, fs)
    corr = fit_correction(u, f, g, p, fs, jac, *choice.lambdas, intercept)
    p_new = corr.projection(p, fs)
    shift = np.linalg.pinv(p_new) @ (corr.c * fs)  # outputs whose P' u is c: the zero moves
    zero = fitted_zero(calib) - shift if intercept else None
    model = CouplingErrorModel(replace(settings, svr=old.settings.svr), np.ones(layout.n),
                               dict(old.chi), own=dict(old.own), projection=p_new, zero=zero)
    x = u + shift if intercept else u  # the outputs less the model's zero
    v = x @ p_new.T
    exact = model.decouple(x, rotate=False, exact=True)
    units = settings.units.loads or None
    r2 = 1.0 - ((v - f) ** 2).sum(axis=0) / ((v - v.mean(axis=0)) ** 2).sum(axis=0)
    before = old.report
    model.report = FitReport(
        r2=dict(zip(layout.labels, map(float, r2), strict=True)),
        n_points={a: int((f[:, i] != 0).sum()) for i, a in enumerate(layout.labels)},
        gamma_before=interference_errors(calib.points, v, fs, layout, units),
        gamma_after=interference_errors(calib.points, exact, fs, layout, units),
        n_support_vectors=dict(before.n_support_vectors) if before else {},
        surrogate_max_error=before.surrogate_max_error if before else None,
        repetitions=calib.repetitions, warnings=[*calib.warnings, choice.line()])
    model.matrix = fit_calibration_matrix(u, f).C
    model.provenance = {**provenance(calib),
                        "prior": {"path": choice.source, "created": getattr(old, "created", "")}}
    model.created = datetime.now(UTC).replace(microsecond=0).isoformat()
    return model


def fit_with_prior(calib, settings, old, source: str, refit, *, method: str | None = None,
                   tune: bool = False, workers: int | None = None) -> CouplingErrorModel:
    """``fit NEW --prior OLD.json``: the candidate of least held-out error (:func:`choose_prior`);
    ``refit(calib)`` fits a set as ``fit`` does (a fresh fit, or one with prior rows)."""
    note = check_prior_options(method, tune, settings)
    if note is not None:
        calib = replace(calib, warnings=(*calib.warnings, note))
    choice = choose_prior(calib, settings, old, source, workers=workers)
    if choice.lambdas is not None:
        return corrected_model(calib, settings, old, choice)
    out = with_prior(calib, old, choice.copies, source)
    return refit(replace(out, warnings=(*out.warnings, choice.line())))


def zero_shift(old, u: np.ndarray, f: np.ndarray) -> np.ndarray:
    """delta (M,) such that the old model decodes u - delta closest to the applied loads f.

    The new set's offsets come from its own few rows (zero: intercept absorbs the mean of
    their nonlinearity, which depends on the poses chosen), and the old model was zeroed
    by another set's: one Gauss-Newton step on f_old(u - delta) = f, the Jacobian of eq.
    (11) by central differences at the rows' mean output, puts both on one zero, the
    in-situ recalibration of the offsets with the known model.
    """
    m = u.shape[1]
    step = np.maximum(np.abs(u).max(axis=0), 1e-12) * 1e-4
    jac = _central(lambda x: old.decouple(x, rotate=False, exact=True),
                   u.mean(axis=0, keepdims=True), step)[0]  # (N, M)
    r = (old.decouple(u, rotate=False, exact=True) - f).mean(axis=0)
    delta, *_ = np.linalg.lstsq(jac, r, rcond=None)
    return delta if np.isfinite(delta).all() else np.zeros(m)


def with_prior(calib, old, lam: int, source: str = "prior"):
    """``calib`` on the old model's zero (:func:`zero_shift`) with ``lam`` copies of each
    row, their loads replaced by the old model's."""
    if lam == 0:
        return calib
    layout = calib.layout
    outputs = list(layout.outputs)
    pts = calib.points.copy()
    u = pts[outputs].to_numpy(dtype=float)
    delta = zero_shift(old, u, pts[list(layout.loads)].to_numpy(dtype=float))
    pts[outputs] = u - delta
    offsets = calib.offsets.copy()
    offsets[outputs] = offsets[outputs].to_numpy(dtype=float) + delta
    calib = replace(calib, points=pts, offsets=offsets)
    f_old = old.decouple(pts[outputs].to_numpy(dtype=float), rotate=False, exact=True)
    prior = pts.copy()
    prior[list(layout.loads)] = f_old
    prior["file"] = f"{source} (prior)"
    copies = pd.concat([pts, *([prior] * lam)], ignore_index=True)
    return replace(calib, points=copies)


