"""The uncertainty budget of every calibrated step, in the manner of EURAMET cg-4.

EURAMET cg-4 v3.0 (2022, "Guidelines on the Uncertainty of Force Measurements"),
in its part on the calibration of force-measuring instruments, and ISO 376:2011
(Annex C) combine *relative* standard uncertainties w_i in quadrature,
w_c = sqrt(sum w_i^2), and state W = k w_c with k = 2.  (cg-4 v2.0's Section 4,
cited here before, covers national force standard machines, not instruments.)
Per component and non-zero load step L (figures of :mod:`.iso376`, X the step's
deflections, X_mean their mean), :data:`CONTRIBUTIONS`:

* ``reference``: (reference_uncertainty / 100) / 2, the config's relative expanded
  uncertainty of the applied loads at k = 2;
* ``reproducibility``: s(X_i) / (sqrt(n) |X_mean|), the standard deviation of the
  mean of the n repetitions; 0 with one;
* ``repeatability``: b' / (100 2 sqrt 3), half the spread of repetitions 1 and 2
  taken as the half-width of a rectangular distribution;
* ``resolution``: sqrt(2) (r / (2 sqrt 3)) / |X_mean|, r the step the readings are
  recorded in; a deflection is the difference of two readings;
* ``reversibility``: v / (100 sqrt 3) where the sweeps return through the step;
* ``interpolation``: |f_c| / (100 sqrt 3);
* ``zero``: |i_f - i_0| / (sqrt 3 |X_mean|), the largest zero drift of the step's
  load sign over a sweep, relative to *this* step's deflection (relative to X_N it
  would understate the small steps);
* ``temperature``: |K_T| dT / (2 sqrt 3) where the calibration has a
  ``temperature`` column: K_T the relative change of the deflections per kelvin
  (least squares over the sweep's steps), dT the range of temperature;
* ``drift``: d / sqrt 3, the relative change between two calibrations of the
  sensor (``compare --json`` at this load, or the config's ``drift`` [%]);
* ``model``: u_model / |L|, fsdecouple's own addition, not a cg-4 contribution:
  the root mean square error of the decoupled prime force on held-out points at
  that step, in quadrature with the RMS error of the same component on held-out
  points where only other components are loaded (the interference, eq. 12).

U = W |L| = 2 w_c |L|, in the load unit.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from ..data.calibration import CalibrationSet
from ..data.zero import mean_offset_variance, out_and_back, shift_variance, zero_row_shift
from .intervals import interval_calibration
from .iso376 import ComponentSteps, component_steps, resolution
from .sweep_model import fit_sweep_model

CONTRIBUTIONS = ("reference", "reproducibility", "repeatability", "resolution", "reversibility",
                 "interpolation", "zero", "temperature", "drift", "model")
CG4 = "EURAMET cg-4 v3.0 (2022), calibration of force-measuring instruments"
SOURCES = {
    "reference": f"{CG4}; ISO 376:2011 Annex C and Table 3 (calibration force)",
    "reproducibility": f"{CG4}; ISO 376:2011 Annex C (b)",
    "repeatability": f"{CG4}; ISO 376:2011 Annex C (b')",
    "resolution": f"{CG4}; ISO 376:2011 Annex C (r)",
    "reversibility": f"{CG4} (v / sqrt 3)",
    "interpolation": f"{CG4}; ISO 376:2011 Annex C (f_c)",
    "zero": f"{CG4}; ISO 376:2011 Annex C (f_0, here per step)",
    "temperature": f"{CG4}; ISO 376:2011 Annex C (temperature)",
    "drift": f"{CG4} (drift between calibrations)",
    "model": "fsdecouple's own addition (held-out error of the decoupled force, eq. 11 and 12)",
}
K = 2.0  # coverage factor of the expanded uncertainty
TEMPERATURE = "temperature"  # the points' column of the calibration's temperature [°C or K]


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
           r: float, temperature: float = 0.0, drift=0.0) -> dict[str, np.ndarray]:
    """The relative standard uncertainties per step, w_c, W and U [load unit].

    ``temperature``: the relative standard uncertainty of the temperature term
    (:func:`temperature_term`); ``drift``: the relative change between calibrations,
    per step or one for all [fraction, not %].
    """
    X, mean = steps.X, steps.mean
    n = np.isfinite(X).sum(axis=1)
    absx, absl = np.abs(mean), np.abs(steps.loads)
    size = absl.size
    w = {"reference": np.full(size, reference_uncertainty / 100.0 / K)}
    root3 = np.sqrt(3.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        sd = np.nanstd(X, axis=1, ddof=1) if X.shape[1] >= 2 else np.full(size, np.nan)
        w["reproducibility"] = np.where(n >= 2, sd / np.sqrt(n) / absx, 0.0)
    w["repeatability"] = np.nan_to_num(steps.figures["b_prime"]) / 100.0 / (2.0 * root3)
    w["resolution"] = np.sqrt(2.0) * r / (2.0 * root3) / absx
    w["reversibility"] = np.nan_to_num(np.abs(steps.figures["v"])) / 100.0 / root3
    w["interpolation"] = np.nan_to_num(np.abs(steps.figures["f_c"])) / 100.0 / root3
    drift0 = np.array([steps.zero_drift.get(float(np.sign(f)), 0.0) for f in steps.loads])
    w["zero"] = drift0 / root3 / absx
    w["temperature"] = np.full(size, float(temperature))
    w["drift"] = np.broadcast_to(np.abs(np.asarray(drift, dtype=float)), (size,)) / root3
    w["model"] = np.asarray(u_model, dtype=float) / absl
    wc = np.sqrt(sum(v ** 2 for v in w.values()))
    return {**w, "w_c": wc, "W": K * wc, "U": K * wc * absl}


def temperature_term(calib: CalibrationSet, steps: ComponentSteps) -> float | None:
    """The relative standard uncertainty of the temperature term, or None without a
    ``temperature`` column.

    K_T [1/K]: the least-squares slope of X_i / X_mean - 1 against the temperature of
    each first reading of the component's steps; the term is |K_T| dT / (2 sqrt 3),
    dT the range of temperature over the calibration's points.
    """
    if TEMPERATURE not in calib.points.columns:
        return None
    temps = calib.points[TEMPERATURE].to_numpy(dtype=float)
    if not np.isfinite(temps).all():
        return None
    s = calib.sweep(steps.axis)
    col = calib.layout.loads[steps.index]
    rel, t = [], []
    for r, rep in enumerate(steps.repetitions):
        g = s[s["repetition"] == rep].drop_duplicates(col)
        for j, load in enumerate(steps.loads):
            hit = g[g[col] == load]
            if len(hit) and np.isfinite(steps.X[j, r]):
                rel.append(steps.X[j, r] / steps.mean[j] - 1.0)
                t.append(float(hit[TEMPERATURE].iloc[0]))
    t_arr, rel_arr = np.asarray(t), np.asarray(rel)
    spread = float(np.ptp(temps))
    if t_arr.size < 2 or np.ptp(t_arr) == 0.0:
        return 0.0
    slope = np.polyfit(t_arr - t_arr.mean(), rel_arr, 1)[0]
    return abs(float(slope)) * spread / (2.0 * np.sqrt(3.0))


def step_budgets(calib: CalibrationSet, u_models: dict[str, np.ndarray],
                 reference_uncertainty: float) -> list[tuple[ComponentSteps, dict]]:
    """Every component's steps and budget; ``u_models``: u_model per step, by component."""
    out = []
    for a, axis in enumerate(calib.layout.labels):
        st = component_steps(calib, a)
        out.append((st, budget(st, u_models[axis], reference_uncertainty, resolution(calib, a),
                               temperature_term(calib, st) or 0.0)))
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
    where the intervals centre them, default ``predicted``) (:mod:`fsdecouple.evaluation.intervals`).
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
    sweeps = shares = None
    # an svr model of N outputs: a centre other than eq. (11)'s (intervals.centre)
    shifts = len(layout.outputs) == layout.n and getattr(model, "method", None) == "svr"
    rows = calib.zero == "rows" and np.isfinite(zeros) and {"repetition", "axis"} <= set(points.columns)
    # zero rows of one-way single-axis sweeps: the least-squares sweep model's centre and
    # variance (a lag of sweeps out and back is not in it: docs/design/intervals.md)
    swept = (fit_sweep_model(calib.points, layout)
             if rows and shifts and not out_and_back(calib.points, layout) else None)
    if rows and swept is None:
        # each held-out sweep's own share apart, and the zero readings' known share
        sweeps = points.groupby(["repetition", "axis"], sort=False).ngroup().to_numpy()
        # the zero readings' mean error the model inherits: what the centre's shift
        # leaves of it where the shift is taken back, else all of it
        shares = (shift_variance if shifts else mean_offset_variance)(calib.points, layout)
    cal = interval_calibration(true, predicted if centred is None else centred, layout.labels,
                               noise, zeros, len(calib.repetitions), trained, sweeps, shares)
    if swept is not None:
        cal["least_squares"], cal["deviations"] = swept["model"], swept["deviations"]
    elif shares is not None and shifts:
        cal["zero_shift"] = zero_shift(calib, model.k)
    return {"reference_uncertainty": settings.lab.reference_uncertainty, "steps": steps,
            "interval": cal}


def zero_shift(calib: CalibrationSet, k: np.ndarray) -> dict[str, list[float]]:
    """Per loaded component b, the force every component a of a row takes from the zero
    rows' inherited error [load unit]: shift[b, a] / k_a for a != b (chi_ab's), and
    shift[b, b] ratio_b / k_b per unit of f_b for a = b (omega_b's slope)
    (:func:`fsdecouple.data.zero.zero_row_shift`)."""
    shift, ratio = zero_row_shift(calib.points, calib.offsets, calib.layout)
    k = np.asarray(k, dtype=float)
    out = shift / k[None, :]
    out[np.diag_indices_from(out)] = np.diag(shift) * ratio / k
    return {axis: out[b].tolist() for b, axis in enumerate(calib.layout.labels)}


def heldout_predictions(rounds, models: dict, method: str,
                        forces=None) -> tuple[pd.DataFrame, np.ndarray]:
    """The held-out points of every round (ends too) and their forces by ``method``'s model
    fitted without them.

    ``forces(model, u)``: how a model's forces are computed; default eq. (11) without
    rotation (the intervals pass their centre, :func:`fsdecouple.evaluation.intervals.centre`).
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
