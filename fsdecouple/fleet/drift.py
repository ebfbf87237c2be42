"""Drift between two calibrations of one sensor: slopes, chi and forces, old vs new.

A sensor re-calibrated months later should give the same model within the noise
of its calibration.  :func:`compare` says by how much it does not, per component:

* ``slope_change_pct``: (k_new - k_old) / k_old of eq. (2) [%];
* ``chi_max_pct``: per chi_ab (eq. 4) with output a, the largest |chi_new - chi_old|
  over the prime outputs both calibrations covered, in % of the output's full
  scale |k_a| F_FS,a (the old model's); chi is the exact kernel sum, never its
  surrogate table;
* ``force_max_pct``: the largest |f_new - f_old| by eq. (11) (or by the
  calibration matrix of a ``linear`` model) over a grid of combined outputs
  spanning both models' calibrated ranges, in % of the full-scale load F_FS,a
  (the old model's).  Both models decouple the *same* outputs, so the figure is
  what a log would change by if decoupled with the new model instead of the old.

And ``en``, per component the largest |E_n| over the calibrated steps of both
(:mod:`fsdecouple.fleet.en`): a change told apart from the calibrations' own
uncertainty.  ``passed`` is False when any |E_n| > 1 or, with ``max_drift``, any
figure above exceeds it.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..axes import component_key
from ..core.model import CouplingErrorModel
from ..errors import InputError
from .en import en_figures

FORMAT = "fsdecouple.drift"
CHI_POINTS = 2001  # per chi, over the common range: chi is smooth at this spacing
FORCE_POINTS = 21  # per component: 21^3 combined outputs for a 3-axis sensor


def check_max_drift(max_drift: float | None) -> None:
    """``--max-drift P``: a finite percentage greater than 0, or None."""
    if max_drift is not None and not (math.isfinite(max_drift) and max_drift > 0):
        raise InputError(f"--max-drift {max_drift}: expected a percentage greater than 0, e.g. 0.5")


def compare(old: CouplingErrorModel | str | Path, new: CouplingErrorModel | str | Path, *,
            max_drift: float | None = None, en_gate: bool = True) -> dict[str, Any]:
    """The drift document of ``new`` against ``old`` (models or model files).

    Parameters
    ----------
    old, new : CouplingErrorModel or path
        Two models of the same sensor: same components, same units.
    max_drift : float, optional
        Gate [%]: ``passed`` is False when any slope change, chi difference or
        force difference exceeds it (in absolute value).  Without it, and without
        E_n (a model with no certificate data), ``passed`` is null.
    en_gate : bool
        Whether |E_n| > 1 fails ``passed`` (``compare``); ``fit-many`` gates its
        drift by ``max_drift`` alone and only reports E_n.

    Returns
    -------
    dict
        ``{"format": "fsdecouple.drift", "old", "new", "components": {a:
        {"slope_change_pct", "chi_max_pct": {chi name: %}, "force_max_pct"}},
        "max_drift", "en": {a: max |E_n|} or None, "en_steps", "en_note", "passed",
        "exceeded"}``.
    """
    from ..core.modelfile import load_model

    check_max_drift(max_drift)
    docs = []
    models = []
    for m in (old, new):
        if isinstance(m, str | Path):
            docs.append({"model": str(m)})
            m = load_model(m)
        else:
            docs.append({"model": None})
        docs[-1].update(sensor=m.settings.sensor, created=m.created, method=m.method)
        models.append(m)
    old, new = models
    for m in models:
        if not m.imported:  # a factory matrix's extra output is its thermistor
            m.layout.one_output_each("compare")
    _check_comparable(old, new, docs[0]["model"] or "old model", docs[1]["model"] or "new model")

    axes = old.layout.labels
    fso = old.full_scale_output
    fs = np.asarray(old.settings.full_scale, dtype=float)
    # an imported factory matrix (data/ati_cal.py) has no slopes and no chi of its own:
    # only the forces compare, on loads within the full scale
    factory = next((m for m in (old, new) if m.imported), None)
    slope = [None] * len(axes) if factory else 100.0 * (new.k - old.k) / old.k
    chi_pct: dict[str, dict[str, float]] = {a: {} for a in axes}
    for name, c_old in ({} if factory else old.chi).items():
        c_new = new.chi[name]
        lo = max(c_old.input_range[0], c_new.input_range[0])
        hi = min(c_old.input_range[1], c_new.input_range[1])
        if not _shared(lo, hi, c_old.input_range, c_new.input_range):
            raise InputError(f"chi {name}: the two calibrations share less than "
                             f"{100 * MIN_SHARED:.0f} % of their ranges of "
                             f"{_output(old, c_old.input_axis)} "
                             f"(old {_range(c_old.input_range)}, new {_range(c_new.input_range)})")
        u = np.linspace(lo, hi, CHI_POINTS)
        diff = np.abs(c_new(u) - c_old(u)).max()
        chi_pct[axes[c_old.output_axis]][name] = float(100.0 * diff / fso[c_old.output_axis])
    u = _output_grid(old, new) if factory is None else _load_grid(factory)
    f_old = old.decouple(u, rotate=False, exact=True)
    f_new = new.decouple(u, rotate=False, exact=True)
    force = 100.0 * np.abs(f_new - f_old).max(axis=0) / fs

    components = {
        a: {"slope_change_pct": None if slope[i] is None else float(slope[i]),
            "chi_max_pct": chi_pct[a],
            "force_max_pct": float(force[i])}
        for i, a in enumerate(axes)
    }
    exceeded = [] if max_drift is None else _exceeded(components, max_drift)
    en, why = en_figures(old, new)
    unit = old.settings.units.load
    if en is not None and en_gate:
        exceeded += [f"{s['axis']}: E_n {s['en']:+.2f} at {s['load']:g} {unit} ({s['steps_of']}'s step)"
                     for s in en["steps"] if abs(s["en"]) > 1.0][:5]
    gated = max_drift is not None or (en is not None and en_gate)
    return {
        "temperature": temperature_drift(old, new),
        "format": FORMAT,
        "old": docs[0],
        "new": docs[1],
        "units": {"load": unit, "output": old.settings.units.output},
        "components": components,
        "max_drift": max_drift,
        "en": None if en is None else en["en"],
        "en_steps": None if en is None else en["steps"],
        "en_note": why,
        "en_gate": en is not None and en_gate,
        "passed": None if not gated else not exceeded,
        "exceeded": exceeded,
    }


def temperature_drift(old: CouplingErrorModel, new: CouplingErrorModel) -> dict[str, Any] | None:
    """Per output, the change of the offset drift b_i and gain drift g_i (new - old) and of
    T0 (core/temperature.py); None when neither model has temperature terms."""
    t_old, t_new = old.temperature, new.temperature
    if t_old is None and t_new is None:
        return None
    if t_old is None or t_new is None:
        which = "old" if t_old is None else "new"
        return {"note": f"the {which} model has no temperature terms: nothing to compare"}
    if t_old.channel != t_new.channel or t_old.unit != t_new.unit:
        return {"note": "the two models' temperatures are different channels or units"}
    outputs = [o for i, o in enumerate(old.layout.outputs) if i != t_old.channel]
    keep = [i for i in range(old.n_outputs) if i != t_old.channel]
    return {"unit": t_old.unit, "t0_change": float(t_new.t0 - t_old.t0),
            "b_change": dict(zip(outputs, map(float, t_new.b[keep] - t_old.b[keep]), strict=True)),
            "g_change": dict(zip(outputs, map(float, t_new.g[keep] - t_old.g[keep]), strict=True))}


def largest(doc: dict[str, Any]) -> float:
    """The largest drift figure of a drift document, in absolute value [%]."""
    return max(abs(v) for _, v in _figures(doc["components"]))


def _output(model: CouplingErrorModel, b: int) -> str:
    return f"u_{model.layout.labels[b]}" if model.layout.is_default else model.layout.outputs[b]


def _figures(components):
    for a, c in components.items():
        if c["slope_change_pct"] is not None:  # None: an imported factory matrix
            yield f"{a}: slope change", c["slope_change_pct"]
        for name, v in c["chi_max_pct"].items():
            yield f"chi {name}", v
        yield f"{a}: force", c["force_max_pct"]


def _exceeded(components, max_drift: float) -> list[str]:
    return [f"{what} {v:+.3f} %" if what.endswith("slope change") else f"{what} {v:.3f} %"
            for what, v in _figures(components) if abs(v) > max_drift]


def _range(r) -> str:
    return f"[{r[0]:.6g}, {r[1]:.6g}]"


def _check_comparable(old: CouplingErrorModel, new: CouplingErrorModel, a: str, b: str) -> None:
    chis_differ = sorted(old.chi) != sorted(new.chi) and not (old.imported or new.imported)
    if old.n_components != new.n_components or chis_differ:
        raise InputError(f"{b}: has {new.n_components} components ({', '.join(new.layout.labels)}), "
                         f"{a} has {old.n_components} ({', '.join(old.layout.labels)}); "
                         "compare two calibrations of one sensor")
    if not same_components(old.layout.labels, new.layout.labels):
        raise InputError(f"{b}: its components are {', '.join(new.layout.labels)}, {a}'s "
                         f"{', '.join(old.layout.labels)}; compare two calibrations of one sensor")
    if old.n_outputs != new.n_outputs:
        raise InputError(f"{b}: takes {new.n_outputs} outputs ({', '.join(new.layout.outputs)}), "
                         f"{a} {old.n_outputs} ({', '.join(old.layout.outputs)}); compare two "
                         "calibrations of one sensor")
    if old.settings.units != new.settings.units:
        raise InputError(f"{b}: is in {new.settings.units.load} and {new.settings.units.output}, "
                         f"{a} in {old.settings.units.load} and {old.settings.units.output}; "
                         "compare models in the same units")


def same_components(a, b) -> bool:
    """Whether two models' component names are one sensor's, in the same order: names may
    differ only in case and as ATI's torques (``tx``, data/ati_model.py) against
    fsdecouple's moments (``mx``)."""
    return [component_key(x) for x in a] == [component_key(x) for x in b]


# The range both calibrations cover must be at least this fraction of each one's span:
# ranges that meet only at 0 (one calibrated in tension, one in compression) share a
# point, where every chi is near 0, and would report a drift of nothing.
MIN_SHARED = 0.1


def _shared(lo: float, hi: float, r_old, r_new) -> bool:
    span = hi - lo
    return bool(span >= MIN_SHARED * (r_old[1] - r_old[0]) and span >= MIN_SHARED * (r_new[1] - r_new[0])
                and span > 0)


def _load_grid(factory: CouplingErrorModel) -> np.ndarray:
    """Outputs (n, M) whose forces by the factory matrix C span +-F_FS in every component:
    u = C^+ f over a grid of loads, seven a component for six."""
    fs = np.asarray(factory.settings.full_scale, dtype=float)
    n = factory.n_components
    k = FORCE_POINTS if n <= 3 else max(3, int(2e5 ** (1 / n)))
    f = np.stack(np.meshgrid(*[np.linspace(-v, v, k) for v in fs], indexing="ij"),
                 axis=-1).reshape(-1, n)
    return f @ np.linalg.pinv(factory.matrix).T


def _output_grid(old: CouplingErrorModel, new: CouplingErrorModel) -> np.ndarray:
    """Combined outputs spanning the calibrated range both models cover, shape (n, N) [V]."""
    r_old, r_new = old.calibrated_range, new.calibrated_range
    lo, hi = np.maximum(r_old[:, 0], r_new[:, 0]), np.minimum(r_old[:, 1], r_new[:, 1])
    bad = [i for i in range(len(lo)) if not _shared(lo[i], hi[i], r_old[i], r_new[i])]
    if bad:
        a = old.layout.labels[bad[0]]
        raise InputError(f"component {a}: the two calibrations share less than "
                         f"{100 * MIN_SHARED:.0f} % of their ranges of {_output(old, bad[0])} "
                         f"(old {_range(r_old[bad[0]])}, new {_range(r_new[bad[0]])})")
    # 21 points a component for three (9261 vectors); fewer for more components,
    # so the grid stays near 10^5 vectors (seven a component for six)
    n = FORCE_POINTS if len(lo) <= 3 else max(3, int(2e5 ** (1 / len(lo))))
    axes = [np.linspace(lo[i], hi[i], n) for i in range(len(lo))]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(lo))
