"""The ISO 376 figures of a calibration, step by step, and the class they allow.

For each component and each non-zero load step of its own sweeps, X_i is the
zero-corrected prime output of repetition i at that step (the first time the
sweep reaches that load: the increasing series).  In percent, as ISO 376:2011
(Section 7.5) states them:

* ``b``, reproducibility: 100 (max_i X_i - min_i X_i) / |mean_i X_i|, over all
  repetitions (two or more);
* ``b_prime``, repeatability: 100 |X_2 - X_1| / |(X_1 + X_2) / 2|, from the first
  two repetitions;
* ``f_c``, interpolation: 100 (X_mean - X_a) / X_a, with X_a a polynomial in the load
  *without* constant term, of degree 3 (one less when a load sign has at most 3
  steps), fitted by least squares to the step means X_mean of all steps of the same
  load sign;
* ``f_0``, zero error: 100 (i_f - i_0) / X_N for a sweep with zero rows at its start
  and its end (i_0, i_f the first and last zero reading, X_N the deflection at the
  sweep's largest load); stated at that largest step, the largest over repetitions;
* ``v``, reversibility: 100 (X' - X) / |X| where a sweep loads up and then down and
  reads the step again (X' on the way down), averaged over repetitions.

A class per component and load sign (:data:`CLASS_LIMITS`) comes from b, b' and f_c
over the steps at or above 10 % of full scale.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..data.calibration import CalibrationSet

# ISO 376:2011, Table 2 (characteristics of force-proving instruments), in percent:
# the largest relative reproducibility b, repeatability b' and interpolation error
# |f_c| a class allows.  (Its zero, reversibility and creep limits need series
# this calibration does not always have: they are shown, not classed.)
CLASS_LIMITS = (
    ("00", {"b": 0.05, "b_prime": 0.025, "f_c": 0.025}),
    ("0.5", {"b": 0.10, "b_prime": 0.05, "f_c": 0.05}),
    ("1", {"b": 0.20, "b_prime": 0.10, "f_c": 0.10}),
    ("2", {"b": 0.40, "b_prime": 0.20, "f_c": 0.20}),
)
CLASS_FROM = 0.1  # ISO 376: the class holds from the lower limit, here 10 % of full scale
METRICS = ("b", "b_prime", "f_c", "f_0", "v")


@dataclass
class ComponentSteps:
    """One component's load steps and their figures (arrays over steps, NaN: absent).

    ``X``: shape (steps, repetitions), the zero-corrected prime output [output unit];
    ``outputs``: the mean zero-corrected outputs of all components at each step.
    """

    axis: str
    index: int
    loads: np.ndarray
    repetitions: list[int]
    X: np.ndarray
    outputs: np.ndarray
    figures: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def mean(self) -> np.ndarray:
        return np.nanmean(self.X, axis=1)


def _first_and_return(loads: np.ndarray) -> tuple[dict[float, int], dict[float, int]]:
    """Row of each load on the way up (first reading) and on the way back (a later one)."""
    first: dict[float, int] = {}
    back: dict[float, int] = {}
    peak = int(np.argmax(np.abs(loads))) if loads.size else 0
    for i, f in enumerate(loads):
        if f not in first:
            first[f] = i
        elif i > peak and f != 0.0:
            back.setdefault(f, i)
    return first, back


def component_steps(calib: CalibrationSet, a: int) -> ComponentSteps:
    """The steps of component ``a``'s sweeps, with b, b', f_c, f_0 and v."""
    layout = calib.layout
    axis = layout.labels[a]
    s = calib.sweep(axis)
    reps = sorted(int(r) for r in s["repetition"].unique())
    load_col = layout.loads[a]
    loads = np.unique(s[load_col].to_numpy(dtype=float))
    loads = loads[loads != 0.0]
    X = np.full((loads.size, len(reps)), np.nan)
    back = np.full_like(X, np.nan)
    outputs = np.zeros((loads.size, layout.n))
    counts = np.zeros(loads.size)
    f0 = np.full((2, len(reps)), np.nan)  # per load sign (negative, positive)
    where = {f: j for j, f in enumerate(loads)}
    for r, rep in enumerate(reps):
        g = s[s["repetition"] == rep]
        f = g[load_col].to_numpy(dtype=float)
        u = g[list(layout.outputs)].to_numpy(dtype=float)
        if getattr(calib, "zero_auto", False):  # out-and-back sweeps fitted with zero: fit:
            raw = g[[f"{c}_raw" for c in layout.outputs]].to_numpy(dtype=float)
            u = raw - raw[f == 0.0].mean(axis=0)  # ISO 376 deflections, from the zero rows
        first, again = _first_and_return(f)
        for load, i in first.items():
            if load != 0.0:
                X[where[load], r] = u[i, a]
                outputs[where[load]] += u[i]
                counts[where[load]] += 1
        for load, i in again.items():
            back[where[load], r] = u[i, a]
        if f.size > 2 and f[0] == 0.0 and f[-1] == 0.0 and (f != 0.0).any():
            peak = int(np.argmax(np.abs(f)))
            f0[int(f[peak] > 0), r] = 100.0 * (u[-1, a] - u[0, a]) / abs(u[peak, a])
    steps = ComponentSteps(axis, a, loads, reps, X, outputs / counts[:, None].clip(1))
    steps.figures = _figures(steps, back, f0)
    return steps


def _figures(st: ComponentSteps, back: np.ndarray, f0: np.ndarray) -> dict[str, np.ndarray]:
    X, n = st.X, st.loads.size
    mean = st.mean
    out = {m: np.full(n, np.nan) for m in METRICS}
    have = np.isfinite(X).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        several = have >= 2
        out["b"][several] = (100.0 * (np.nanmax(X, axis=1) - np.nanmin(X, axis=1))
                             / np.abs(mean))[several]
        if X.shape[1] >= 2:
            x1, x2 = X[:, 0], X[:, 1]
            out["b_prime"] = 100.0 * np.abs(x2 - x1) / np.abs((x1 + x2) / 2.0)
        both = np.isfinite(back) & np.isfinite(X)
        returned = both.any(axis=1)
        v = np.where(both, back - X, 0.0).sum(axis=1) / both.sum(axis=1).clip(1)
        out["v"][returned] = (100.0 * v / np.abs(mean))[returned]
    for sign in (-1.0, 1.0):
        idx = np.flatnonzero(np.sign(st.loads) == sign)
        if idx.size >= 2:
            out["f_c"][idx] = interpolation_errors(st.loads[idx], mean[idx])
        vals = f0[int(sign > 0)]
        if idx.size and np.isfinite(vals).any():
            peak = idx[np.argmax(np.abs(st.loads[idx]))]
            out["f_0"][peak] = vals[np.nanargmax(np.abs(vals))]
    return out


def interpolation_errors(loads: np.ndarray, means: np.ndarray) -> np.ndarray:
    """f_c [%] of steps of one load sign: the means against a least-squares polynomial
    without constant term, cubic (ISO 376:2011, 7.5.4) or, with 3 steps or fewer, of
    one degree less than the steps so that it does not pass through every mean."""
    degree = min(3, loads.size - 1)
    scale = np.abs(loads).max()  # a column scaling: the least-squares values do not change
    t = loads / scale
    design = np.column_stack([t ** p for p in range(1, degree + 1)])
    coef, *_ = np.linalg.lstsq(design, means, rcond=None)
    xa = design @ coef
    return 100.0 * (means - xa) / xa


def classify(st: ComponentSteps, full_scale: float) -> dict[str, str]:
    """The ISO 376 class per load sign (``"+"``, ``"-"``) from b, b', f_c at steps >= 10 % F.S.

    ``none`` when no class's limits hold, when no step reaches 10 % of full scale, or
    when b or b' is absent there (one repetition): ISO 376 classes need both.
    """
    out = {}
    for sign, name in ((1.0, "+"), (-1.0, "-")):
        idx = np.flatnonzero((np.sign(st.loads) == sign)
                             & (np.abs(st.loads) >= CLASS_FROM * full_scale * (1 - 1e-12)))
        if not (np.sign(st.loads) == sign).any():
            continue
        chosen = "none"
        measured = idx.size and all(np.isfinite(st.figures[m][idx]).all() for m in ("b", "b_prime"))
        for cls, limits in CLASS_LIMITS if measured else ():
            worst = {m: np.abs(st.figures[m][idx]) for m in limits}
            if all(np.all(~np.isfinite(w) | (w <= limits[m])) for m, w in worst.items()):  # f_c: 2+ steps
                chosen = cls
                break
        out[name] = chosen
    return out


def resolution(calib: CalibrationSet, a: int) -> float:
    """The resolution r of output ``a``'s readings [output unit]: the step they are recorded in.

    Readings printed to k decimals (or whole ADC counts, k = 0) are multiples of
    10^-k: r is the largest such step all readings are multiples of, for k up to 12.
    Readings with more digits than that give the smallest difference between two
    distinct readings instead; 0 when every reading is the same.
    """
    col = f"{calib.layout.outputs[a]}_raw"
    values = np.unique(calib.points[col].to_numpy(dtype=float))
    for k in range(0, 13):
        scaled = values * 10.0 ** k
        # a double holds ~16 digits: allow its rounding, never a fraction of the step
        tol = np.maximum(1e-6, 8.0 * np.finfo(float).eps * np.abs(scaled))
        if np.all(np.abs(scaled - np.round(scaled)) <= tol):
            return 10.0 ** -k
    steps = np.diff(values)
    steps = steps[steps > 1e-12 * max(1.0, float(np.abs(values).max(initial=0.0)))]
    return float(steps.min()) if steps.size else 0.0
