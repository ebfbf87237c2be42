"""In-situ recalibration toward a previous model (issue 32 item 7): ``fit NEW --prior OLD.json``.

A sensor recalibrated in place (a few poses on the robot it is mounted on) has too few
points for a fresh fit, and its old model has drifted.  robotology's in-situ calibration
fits the new matrix by ridge regression toward the previous one,

    C = argmin ||F - C U||^2 + lambda ||C - C_old||^2,

which is least squares on the new rows plus lambda times "pseudo-rows" on which the old
matrix is the truth.  Extended to omega and the chi: the new set's own zero-corrected
outputs u are given, besides their applied loads, the loads the old model decodes from
them, f_old = old.decouple(u) (eq. 11), as extra calibration rows; the fit (eqs. 2, 4,
10) then shrinks every slope and every chi toward the old model's, by as much as lambda
(prior rows per new row) weighs them.  lambda is chosen from :data:`LAMBDAS` by held-out
error: K folds of the new rows, each scored on its held-out rows' worst component's RMS
error (a fraction of full scale) of a fit to the other rows with their pseudo-rows; 0 is
a fresh fit, so the prior is used only where it measured better.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import InputError

LAMBDAS = (0, 1, 2, 4)  # prior rows per new row: a whole number of copies, 0 a fresh fit
FOLDS = 5


@dataclass(frozen=True)
class PriorChoice:
    """lambda chosen, and each candidate's held-out worst component's RMS error [F.S.]."""

    source: str
    lam: int
    scores: dict[int, float]

    def line(self) -> str:
        shown = ", ".join(f"{lam}: {100 * s:.3g} %" for lam, s in self.scores.items())
        return (f"prior model {self.source}: lambda = {self.lam} prior rows per new row, chosen by "
                f"held-out worst component's RMS error ({shown} F.S.; 0 is a fresh fit)")


def check_prior(old, settings, source: str) -> None:
    """The old model must decode the same outputs into the same loads, in the same units."""
    if old.layout != settings.layout or old.settings.units != settings.units:
        raise InputError(f"prior model {source}: the model's outputs and loads "
                         f"({', '.join(old.layout.outputs)} -> {', '.join(old.layout.loads)}, "
                         f"{old.settings.output_unit} -> {old.settings.load_unit}) are not the "
                         "config's; a prior must be a model of the same sensor and layout",
                         argument="prior")


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
    mean = u.mean(axis=0, keepdims=True)
    jac = np.column_stack([
        (old.decouple(mean + step[j] * np.eye(m)[j], rotate=False, exact=True)
         - old.decouple(mean - step[j] * np.eye(m)[j], rotate=False, exact=True))[0] / (2 * step[j])
        for j in range(m)])  # (N, M)
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


def choose_lambda(calib, settings, old, source: str, *, folds: int = FOLDS,
                  workers: int | None = None, lambdas=LAMBDAS) -> PriorChoice:
    """lambda from ``lambdas`` by held-out error over ``folds`` folds of the new rows."""
    from .fit import fit

    check_prior(old, settings, source)
    n = len(calib.points)
    if n < folds:
        raise InputError(f"prior model {source}: {n} calibration rows; choosing lambda needs at "
                         f"least {folds} (one per fold)", argument="prior")
    layout = calib.layout
    order = np.random.default_rng(0).permutation(n)
    fs = np.asarray(settings.full_scale, dtype=float)
    scores = {}
    for lam in lambdas:
        errors = []
        for k in range(folds):
            test = np.zeros(n, dtype=bool)
            test[order[k::folds]] = True
            train = with_prior(calib.select(~test), old, lam, source)
            try:
                model = fit(train, settings, workers=workers, tables=False)
            except InputError:
                errors = None  # too few rows left to fit without the prior
                break
            held = calib.points[test]
            outputs = list(layout.outputs)
            delta = (train.offsets[outputs].to_numpy(dtype=float)
                     - calib.offsets[outputs].to_numpy(dtype=float)).mean(axis=0)
            f = model.decouple(held[outputs].to_numpy(dtype=float) - delta, rotate=False,
                               exact=True)
            errors.append(f - held[list(layout.loads)].to_numpy(dtype=float))
        if errors is not None:
            e = np.concatenate(errors)
            scores[lam] = float((np.sqrt((e ** 2).mean(axis=0)) / fs).max())
    if not scores:
        raise InputError(f"prior model {source}: no lambda could be scored held out",
                         argument="prior")
    best = min(scores, key=lambda lam: (scores[lam], lam))
    return PriorChoice(str(Path(source)), best, scores)


def prior_set(calib, settings, old, source: str, *, workers: int | None = None):
    """The calibration set ``fit --prior`` fits: the new rows and lambda copies of them with
    the old model's loads, lambda chosen by held-out error and said in the set's warnings."""
    choice = choose_lambda(calib, settings, old, source, workers=workers)
    out = with_prior(calib, old, choice.lam, source)
    return replace(out, warnings=(*out.warnings, choice.line()))
