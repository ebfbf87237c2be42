"""The uncertainty budget of every calibrated step, in the manner of EURAMET cg-4.

EURAMET cg-4 (v2.0, 2011, Section 4) combines *relative* standard uncertainties in
quadrature, w_c = sqrt(sum w_i^2), and states W = k w_c with k = 2.  Here, per
component and non-zero load step L (figures of :mod:`fsdecouple.evaluation.iso376`):

* ``reference``: w_1 = (reference_uncertainty / 100) / 2, the config's relative
  expanded uncertainty of the applied loads at k = 2 (cg-4 4.3.1);
* ``reproducibility``: w_2 = s(X_i) / (sqrt(n) |X_mean|), the standard deviation of the
  mean of the n repetitions (cg-4 4.3.2); absent with one repetition;
* ``resolution``: w_3 = sqrt(2) (r / (2 sqrt 3)) / |X_mean|, r the smallest step between
  readings in the data; a deflection is the difference of two readings (cg-4 4.3.3);
* ``interpolation``: w_4 = |f_c| / (100 sqrt 3), the deviation from the fitted curve
  taken as the half-width of a rectangular distribution (cg-4 4.3.6);
* ``zero``: w_5 = |f_0| / (100 sqrt 3), where the sweeps read zero at both ends
  (cg-4 4.3.5);
* ``model``: w_6 = u_model / |L|, the root mean square error of the decoupled prime
  force on held-out points at that step, combined in quadrature with the RMS error
  of the same component on held-out points where only other components are
  loaded: the interference error (eq. 12) a user of that component meets.

U = W |L| = 2 w_c |L|, in the load unit.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from ..core.intervals import interval_calibration
from ..data.calibration import CalibrationSet
from .iso376 import ComponentSteps, component_steps, resolution

CONTRIBUTIONS = ("reference", "reproducibility", "resolution", "interpolation", "zero", "model")
K = 2.0  # coverage factor of the expanded uncertainty


def model_errors(steps: ComponentSteps, points: pd.DataFrame, predicted: np.ndarray,
                 layout) -> np.ndarray:
    """u_model per step [load unit]: held-out RMS prime error (+) interference, in quadrature.

    ``points``: the held-out points (their ``axis`` and loads); ``predicted``: their
    decoupled forces, shape (n, N), by models not fitted on them.
    """
    a = steps.index
    axis = points["axis"].to_numpy()
    true = points[list(layout.loads)].to_numpy(dtype=float)
    err = predicted[:, a] - true[:, a]
    other = axis != steps.axis
    interference = float(np.sqrt(np.mean(err[other] ** 2))) if other.any() else 0.0
    out = np.full(steps.loads.size, np.nan)
    mine = ~other
    for j, load in enumerate(steps.loads):
        at = mine & (true[:, a] == load)
        if at.any():
            out[j] = np.sqrt(np.mean(err[at] ** 2) + interference ** 2)
    # a step no held-out point reached (levels protocol, its end points): the largest
    # error of the component's other steps stands for it
    return np.where(np.isfinite(out), out, np.nanmax(out, initial=interference))


def budget(steps: ComponentSteps, u_model: np.ndarray, reference_uncertainty: float,
           r: float) -> dict[str, np.ndarray]:
    """The relative standard uncertainties per step, w_c, W and U [load unit]."""
    X, mean = steps.X, steps.mean
    n = np.isfinite(X).sum(axis=1)
    absx, absl = np.abs(mean), np.abs(steps.loads)
    w = {"reference": np.full(absl.size, reference_uncertainty / 100.0 / K)}
    with np.errstate(invalid="ignore", divide="ignore"):
        sd = np.nanstd(X, axis=1, ddof=1) if X.shape[1] >= 2 else np.full(absl.size, np.nan)
        w["reproducibility"] = np.where(n >= 2, sd / np.sqrt(n) / absx, 0.0)
    w["resolution"] = np.sqrt(2.0) * r / (2.0 * np.sqrt(3.0)) / absx
    w["interpolation"] = np.nan_to_num(np.abs(steps.figures["f_c"])) / 100.0 / np.sqrt(3.0)
    f0 = steps.figures["f_0"]
    zero = np.nanmax(np.abs(f0)) if np.isfinite(f0).any() else 0.0  # the sweep's, every step
    w["zero"] = np.full(absl.size, zero / 100.0 / np.sqrt(3.0))
    w["model"] = np.asarray(u_model, dtype=float) / absl
    wc = np.sqrt(sum(v ** 2 for v in w.values()))
    return {**w, "w_c": wc, "W": K * wc, "U": K * wc * absl}


def step_budgets(calib: CalibrationSet, u_models: dict[str, np.ndarray],
                 reference_uncertainty: float) -> list[tuple[ComponentSteps, dict]]:
    """Every component's steps and budget; ``u_models``: u_model per step, by component."""
    out = []
    for a, axis in enumerate(calib.layout.labels):
        st = component_steps(calib, a)
        out.append((st, budget(st, u_models[axis], reference_uncertainty, resolution(calib, a))))
    return out


def reading_noise(calib: CalibrationSet, k: np.ndarray) -> tuple[np.ndarray, float]:
    """Per component, the noise s of one reading in the decoupled force [load unit], and
    the mean number m of zero readings per sweep.

    In every sweep, output a's zero-corrected readings Y (steps x repetitions) less
    their step means and their repetition means (a sweep's zero reading is common to
    its steps) leave the noise: s^2 = sum D^2 / ((steps - 1)(repetitions - 1)), pooled
    over the sweeps (a two-way analysis of variance without interaction).  NaN with
    one repetition.
    """
    layout = calib.layout
    sums, dof = np.zeros(layout.n), np.zeros(layout.n)
    zeros = []
    for axis in layout.labels:
        s = calib.sweep(axis)
        loaded = ~(s[list(layout.loads)].to_numpy() == 0.0).all(axis=1)
        reps = s["repetition"].to_numpy()
        zeros.append((~loaded).sum() / max(1, np.unique(reps).size))
        step = s[layout.loads[layout.index(axis)]].to_numpy()
        table = s[loaded].assign(_step=step[loaded]).drop_duplicates(["repetition", "_step"])
        for a, out in enumerate(layout.outputs):
            Y = table.pivot(index="_step", columns="repetition", values=out).dropna().to_numpy()
            if Y.shape[0] < 2 or Y.shape[1] < 2:
                continue
            D = Y - Y.mean(axis=1, keepdims=True)
            D = D - D.mean(axis=0, keepdims=True)
            sums[a] += float((D ** 2).sum())
            dof[a] += (Y.shape[0] - 1) * (Y.shape[1] - 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        noise = np.sqrt(sums / dof) / np.abs(np.asarray(k, dtype=float))
    return np.where(dof > 0, noise, np.nan), max(1.0, float(np.mean(zeros)))


def certificate_data(calib: CalibrationSet, model, points: pd.DataFrame,
                     predicted: np.ndarray, trained: float = 1.0,
                     centred: np.ndarray | None = None) -> dict[str, Any]:
    """What the model file keeps for ``certificate``, ``compare`` (E_n) and ``apply --interval``.

    Per component: the step loads [load unit], the mean zero-corrected outputs of
    every component at each step [output unit], u_model and U per step [load unit];
    and the held-out residuals' conformal scores (``trained``: the fraction of the
    repetitions each held-out round was fitted on; ``centred``: the same points' forces
    where the intervals centre them, default ``predicted``) (:mod:`fsdecouple.core.intervals`).
    """
    layout, settings = calib.layout, model.settings
    u_models = {axis: model_errors(component_steps(calib, a), points, predicted, layout)
                for a, axis in enumerate(layout.labels)}
    steps = {}
    for st, b in step_budgets(calib, u_models, settings.lab.reference_uncertainty):
        steps[st.axis] = {"load": st.loads.tolist(), "outputs": st.outputs.tolist(),
                          "model_error": u_models[st.axis].tolist(), "U": b["U"].tolist()}
    true = points[list(layout.loads)].to_numpy(dtype=float)
    noise, zeros = reading_noise(calib, model.k)
    if settings.zero_method == "fit":  # offsets fitted to whole sweeps, not read at zero rows
        zeros = np.inf
    return {"reference_uncertainty": settings.lab.reference_uncertainty, "steps": steps,
            "interval": interval_calibration(true, predicted if centred is None else centred,
                                             layout.labels, noise, zeros,
                                             len(calib.repetitions), trained)}


def heldout_predictions(rounds, models: dict, method: str,
                        forces=None) -> tuple[pd.DataFrame, np.ndarray]:
    """The held-out points of every round (ends too) and their forces by ``method``'s model
    fitted without them.

    ``forces(model, u)``: how a model's forces are computed; default eq. (11) without
    rotation (the intervals pass their centre, :func:`fsdecouple.core.intervals.centre`).
    """
    frames, preds = [], []
    for rnd in rounds:
        tests = [t for _, t in rnd.tests] + ([rnd.end] if rnd.end is not None else [])
        for test in tests:
            frames.append(test.points)
            model = models[(rnd.index, method)]
            preds.append(model.decouple(test.voltages, rotate=False) if forces is None
                         else forces(model, test.voltages))
    return pd.concat(frames, ignore_index=True), np.concatenate(preds)
