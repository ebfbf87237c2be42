"""The ISO 376 figures of a calibration, step by step, and the class they allow.

For each component and each non-zero load step of its own sweeps, X_i is the
deflection of repetition i at that step: its prime output less the zero read before
its series (:func:`_series_zeros`), the first time the sweep reaches that load with
|load| rising after a zero reading (ISO 376's increasing series; :func:`_out_and_back`).  In percent, as
ISO 376:2011 (Section 7.5) states them:

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
* ``v``, reversibility: 100 |X'_i - X_i| / |X_i| where sweep i reads the step with
  |load| rising and with |load| falling (X'_i), the largest over the repetitions
  that do (as f_0 and c); absolute, so never negative;
* ``c``, creep: 100 (i_300 - i_30) / X_N where the sweep holds its largest load and
  a time column (config ``creep: {column: ...}``) dates the readings 30 s and
  300 s after it was applied (:mod:`fsdecouple.evaluation.creep`).

The class of each component and load sign (:func:`classing`) is the best whose
ISO 376:2011 Table 2 limits every criterion the sweeps give holds, over the steps
of its class range, no better than Table 3 allows the reference forces'
uncertainty; the range starts at the lower limit ISO 376 ties to the resolution r.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..data.calibration import CalibrationSet

# ISO 376:2011, Table 2 (characteristics of force-proving instruments), in percent:
# the largest relative reproducibility b, repeatability b', interpolation |f_c|,
# zero |f_0|, reversibility v and creep c each class allows.  A criterion the
# calibration does not give (no return, no zero at both ends, no timed hold) is
# not classed; b and b' always are (one repetition: no class).
CLASS_LIMITS = (
    ("00", {"b": 0.05, "b_prime": 0.025, "f_c": 0.025, "f_0": 0.012, "v": 0.07, "c": 0.025}),
    ("0.5", {"b": 0.10, "b_prime": 0.05, "f_c": 0.05, "f_0": 0.025, "v": 0.15, "c": 0.05}),
    ("1", {"b": 0.20, "b_prime": 0.10, "f_c": 0.10, "f_0": 0.050, "v": 0.30, "c": 0.10}),
    ("2", {"b": 0.40, "b_prime": 0.20, "f_c": 0.20, "f_0": 0.10, "v": 0.50, "c": 0.20}),
)
# ISO 376:2011, Table 3: the largest relative expanded uncertainty (k = 2) of the
# calibration forces each class allows [%]
REFERENCE_LIMITS = {"00": 0.01, "0.5": 0.02, "1": 0.05, "2": 0.10}
# ISO 376:2011: the lower limit of the class range, in multiples of the resolution r
RESOLUTION_FACTORS = {"00": 4000.0, "0.5": 2000.0, "1": 1000.0, "2": 500.0}
CLASS_FROM = 0.1  # where the resolution is unknown: the class holds from 10 % of full scale
METRICS = ("b", "b_prime", "f_c", "f_0", "v", "c")
STEPWISE = ("b", "b_prime", "f_c", "v")  # checked at every step of the class range
SWEEPWISE = ("f_0", "c")  # one figure per sweep, stated at its largest step


@dataclass
class ComponentSteps:
    """One component's load steps and their figures (arrays over steps, NaN: absent).

    ``X``: shape (steps, repetitions), the deflections [output unit];
    ``outputs``: the mean zero-corrected outputs of all components at each step;
    ``zero_drift``: per load sign (``-1.0``, ``1.0``), the largest |i_f - i_0| of
    its sweeps with zero rows at both ends [output unit], NaN where none.
    """

    axis: str
    index: int
    loads: np.ndarray
    repetitions: list[int]
    X: np.ndarray
    outputs: np.ndarray
    figures: dict[str, np.ndarray] = field(default_factory=dict)
    zero_drift: dict[float, float] = field(default_factory=dict)

    @property
    def mean(self) -> np.ndarray:
        return np.nanmean(self.X, axis=1)


def _series_zeros(loads: np.ndarray, u: np.ndarray, first: dict[float, int],
                  again: dict[float, int]) -> np.ndarray:
    """Each row's zero reading (ISO 376: a deflection starts from the zero read before
    its series): the zero row read last before the row, else the first after it (a sweep
    from -100 N reads steps before any zero); a step's reading on its way back (X')
    takes its X's, so that X' - X is the readings' own difference (``first``, ``again``:
    :func:`_out_and_back` of ``loads``).  Rows of zero load:
    the mean of the zero rows (only their differences are used)."""
    zeros = np.flatnonzero(loads == 0.0)
    out = np.repeat(u[zeros].mean(axis=0, keepdims=True), len(loads), axis=0)
    loaded = np.flatnonzero(loads != 0.0)
    before = np.searchsorted(zeros, loaded) - 1  # the last zero row before each loaded row
    out[loaded] = u[zeros[np.where(before >= 0, before, 0)]]
    for load, i in again.items():
        out[i] = out[first[load]]
    return out


def _out_and_back(loads: np.ndarray) -> tuple[dict[float, int], dict[float, int]]:
    """Row of each load on its way out (X) and on its way back (X'), if it has one.

    A visit is *out* when |load| rises into it (from a smaller load, from zero, or
    from the other sign; a sweep's first row counts as out: the load was applied
    from zero), *back* when |load| falls into it.  X is a load's first visit out
    after a zero reading (a series with its own zero: -100 .. 100 .. -100 reads -100
    first with no zero before it, and again at the end of its last series), else its
    first visit out, else its first visit (a sweep from -100 to +100 reads the
    negative steps only on their way back); X' its first visit back where X is a
    visit out.  A reading right after one at the same load is a hold (creep), not
    a visit.
    """
    first: dict[float, int] = {}
    out: dict[float, int] = {}
    zeroed: dict[float, int] = {}  # visits out after a zero reading
    back: dict[float, int] = {}
    prev, zero_read = 0.0, False
    for i, f in enumerate(loads):
        if i and loads[i - 1] == f:
            continue
        if f == 0.0:
            zero_read = True
        else:
            rising = abs(f) > abs(prev) or np.sign(f) != np.sign(prev)
            first.setdefault(f, i)
            (out if rising else back).setdefault(f, i)
            if rising and zero_read:
                zeroed.setdefault(f, i)
        prev = f
    return ({f: zeroed.get(f, out.get(f, i)) for f, i in first.items()},
            {f: i for f, i in back.items() if f in out})


def _creep(f: np.ndarray, u: np.ndarray, t: np.ndarray, tol: float = 15.0) -> float:
    """i_300 - i_30 of a sweep holding its largest load [output unit], or NaN.

    The first reading of the hold is taken 30 s after the load was applied; the
    300 s reading is the one dated 270 s after it (within ``tol`` seconds).
    """
    peak = int(np.argmax(np.abs(f)))
    end = peak
    while end + 1 < f.size and f[end + 1] == f[peak]:
        end += 1
    if end == peak:
        return np.nan
    late = np.abs(t[peak + 1:end + 1] - t[peak] - 270.0)
    j = int(np.argmin(late))
    return float(u[peak + 1 + j] - u[peak]) if late[j] <= tol else np.nan


def component_steps(calib: CalibrationSet, a: int, times=None) -> ComponentSteps:
    """The steps of component ``a``'s sweeps, with b, b', f_c, f_0, v and (with
    ``times``, a Series of seconds indexed like ``calib.points``) c."""
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
    drift = np.full((2, len(reps)), np.nan)
    creep = np.full((2, len(reps)), np.nan)
    where = {f: j for j, f in enumerate(loads)}
    # the sweep's columns as arrays once (a frame per repetition cost 0.1 s a verdict fit)
    rep_of = s["repetition"].to_numpy()
    f_all = s[load_col].to_numpy(dtype=float)
    u_all = s[list(layout.outputs)].to_numpy(dtype=float)
    for r, rep in enumerate(reps):
        mine = rep_of == rep
        f, u = f_all[mine], u_all[mine]
        first, again = _out_and_back(f)
        if (f == 0.0).any():
            # ISO 376's deflections start from the zero read before their series, whatever
            # zeroed the set for the fit (offsets fitted from all points, or the mean of
            # the sweep's zero rows: out and back, half a lag's return zero); the set's
            # outputs less one offset a sweep, so their differences are the readings'
            # (at T0 where the set was corrected for temperature)
            u = u - _series_zeros(f, u, first, again)
        for load, i in first.items():
            X[where[load], r] = u[i, a]
            outputs[where[load]] += u[i]
            counts[where[load]] += 1
        for load, i in again.items():
            back[where[load], r] = u[i, a]
        if f.size and (f != 0.0).any():
            peak = int(np.argmax(np.abs(f)))
            sign = int(f[peak] > 0)
            if f.size > 2 and f[0] == 0.0 and f[-1] == 0.0:
                drift[sign, r] = u[-1, a] - u[0, a]
                f0[sign, r] = 100.0 * drift[sign, r] / abs(u[peak, a])
            if times is not None:
                t = np.asarray(times.loc[s.index[mine]], dtype=float)
                creep[sign, r] = 100.0 * _creep(f, u[:, a], t) / abs(u[peak, a])
    steps = ComponentSteps(axis, a, loads, reps, X, outputs / counts[:, None].clip(1))
    steps.figures = _figures(steps, back, f0, creep)
    steps.zero_drift = {sign: float(np.nanmax(np.abs(drift[int(sign > 0)])))
                        for sign in (-1.0, 1.0) if np.isfinite(drift[int(sign > 0)]).any()}
    return steps


def _figures(st: ComponentSteps, back: np.ndarray, f0: np.ndarray,
             creep: np.ndarray) -> dict[str, np.ndarray]:
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
        v = np.where(both, np.abs(back - X) / np.abs(X), 0.0).max(axis=1)  # the worst repetition
        out["v"][returned] = 100.0 * v[returned]
    for sign in (-1.0, 1.0):
        idx = np.flatnonzero(np.sign(st.loads) == sign)
        if idx.size >= 2:
            out["f_c"][idx] = interpolation_errors(st.loads[idx], mean[idx])
        peak = idx[np.argmax(np.abs(st.loads[idx]))] if idx.size else None
        for name, per_rep in (("f_0", f0), ("c", creep)):
            vals = per_rep[int(sign > 0)]
            if peak is not None and np.isfinite(vals).any():
                out[name][peak] = vals[np.nanargmax(np.abs(vals))]
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


def lower_limit(cls: str, r: float, full_scale: float, slope: float) -> float:
    """The smallest |load| of class ``cls``'s range [load unit].

    ISO 376:2011 ties it to the resolution r [output unit]: a deflection of at least
    4000 r (class 00), 2000 r (0.5), 1000 r (1) or 500 r (2), here converted to a
    load by the mean sensitivity ``slope`` [output unit / load unit].  Where r is
    unknown (0 or NaN): 10 % of full scale.
    """
    if not (np.isfinite(r) and r > 0 and np.isfinite(slope) and slope > 0):
        return CLASS_FROM * full_scale
    return RESOLUTION_FACTORS[cls] * r / slope


def _failures(st: ComponentSteps, sign: float, cls: str, limits: dict, floor: float,
              reference_uncertainty: float | None) -> list[str]:
    """The criteria that keep a load sign of ``st`` out of class ``cls``."""
    out = []
    if reference_uncertainty is not None and reference_uncertainty > REFERENCE_LIMITS[cls] * (1 + 1e-9):
        out.append("reference")
    mine = np.sign(st.loads) == sign
    idx = np.flatnonzero(mine & (np.abs(st.loads) >= floor * (1 - 1e-12)))
    if not idx.size:
        return [*out, "resolution"]
    for m in ("b", "b_prime"):
        if not np.isfinite(st.figures[m][idx]).all():
            return [*out, "repetitions"]  # ISO 376 classes need both
    for m in STEPWISE:
        w = np.abs(st.figures[m][idx])
        if np.any(np.isfinite(w) & (w > limits[m])):  # f_c: 2+ steps; v: where it returns
            out.append(m)
    for m in SWEEPWISE:
        w = np.abs(st.figures[m][mine])
        if np.any(np.isfinite(w) & (w > limits[m])):
            out.append(m)
    return out


def classing(st: ComponentSteps, full_scale: float, r: float = 0.0,
             reference_uncertainty: float | None = None) -> dict[str, dict]:
    """Per load sign (``"+"``, ``"-"``): ``{"class", "limited_by", "from"}``.

    ``class``: the best of :data:`CLASS_LIMITS` whose every criterion holds, or
    ``none``; ``limited_by``: what keeps it out of the next better class (for
    ``none``: out of class 2), among the criteria of :data:`METRICS`,
    ``reference`` (Table 3's cap by ``reference_uncertainty`` [%, k = 2]),
    ``resolution`` (no step at or above the class range's lower limit) and
    ``repetitions`` (b or b' absent); ``from``: the lower limit of the class's
    range [load unit] (of class 2's for ``none``).  ``r``: the resolution [output
    unit] (:func:`resolution`), 0 if unknown.
    """
    out = {}
    for sign, name in ((1.0, "+"), (-1.0, "-")):
        mine = np.sign(st.loads) == sign
        if not mine.any():
            continue
        with np.errstate(invalid="ignore", divide="ignore"):
            slope = float(np.nanmean(np.abs(st.mean[mine]) / np.abs(st.loads[mine])))
        chosen, start, worse = "none", 0.0, []
        for cls, limits in CLASS_LIMITS:
            start = lower_limit(cls, r, full_scale, slope)
            fails = _failures(st, sign, cls, limits, start, reference_uncertainty)
            if not fails:
                chosen = cls
                break
            worse = fails  # none: class 2's
        out[name] = {"class": chosen, "limited_by": worse, "from": float(start)}
    return out


def classify(st: ComponentSteps, full_scale: float, r: float = 0.0,
             reference_uncertainty: float | None = None) -> dict[str, str]:
    """The class per load sign (``"+"``, ``"-"``): :func:`classing` without the reasons."""
    return {s: c["class"] for s, c in classing(st, full_scale, r, reference_uncertainty).items()}


def resolution(calib: CalibrationSet, a: int) -> float:
    """The resolution r of output ``a``'s readings [output unit]: the step they are recorded in.

    Readings printed to k decimals (or whole ADC counts, k = 0) are multiples of
    10^-k: r is the largest such step all readings are multiples of, for k up to 12.
    Readings with more digits than that give the smallest difference between two
    distinct readings instead; 0 when every reading is the same.  The step is the
    file's: readings a config's ``scale:`` multiplies (counts to volts) are divided by
    it first, and r multiplied by it after (whole counts x 2.5e-7 V: r = 2.5e-7 V).
    """
    name = calib.layout.outputs[a]
    factor = abs(float(calib.settings.scale.get(name, 1.0))) if calib.settings is not None else 1.0
    factor = factor if factor > 0 else 1.0
    values = np.unique(calib.points[f"{name}_raw"].to_numpy(dtype=float)) / factor
    return _step(values) * factor


def _step(values: np.ndarray) -> float:
    """The step of :func:`resolution` of sorted distinct ``values``."""
    for k in range(0, 13):
        scaled = values * 10.0 ** k
        # a double holds ~16 digits: allow its rounding, never a fraction of the step
        tol = np.maximum(1e-6, 8.0 * np.finfo(float).eps * np.abs(scaled))
        if np.all(np.abs(scaled - np.round(scaled)) <= tol):
            return 10.0 ** -k
    steps = np.diff(values)
    steps = steps[steps > 1e-12 * max(1.0, float(np.abs(values).max(initial=0.0)))]
    return float(steps.min()) if steps.size else 0.0
