"""The calibration certificate as plain data: ISO 376 figures, class and uncertainty budget.

:func:`certificate` reads a calibration set against the model fitted on it and
returns the ``fsdecouple.certificate`` document: ``records`` ``[{axis, load, metric,
value}]`` (``b``, ``b_prime``, ``f_c``, ``f_0``, ``v``, ``c`` [%], ``U`` [load unit],
one per component, non-zero load step of its own sweeps and metric; figures a set
cannot give are absent and ``notes`` say why), ``classes`` ``[{axis, sign, class,
limited_by, from}]`` (:func:`fsdecouple.evaluation.iso376.classing`), and the
``budget`` of every step with the ``budget_sources`` of its contributions
(:mod:`fsdecouple.evaluation.budget`).
"""

from __future__ import annotations

from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from ..axes import component_key
from ..config import Settings
from ..core.interval_data import MAX_FULL_SCALES
from ..core.model import CouplingErrorModel
from ..data.calibration import CalibrationSet, excluded_lines
from ..errors import InputError
from ..schema import refuse_unused, unused_warning
from .budget import CONTRIBUTIONS, SOURCES, TEMPERATURE, budget, temperature_term
from .creep import creep_times
from .iso376 import (
    CLASS_FROM,
    CLASS_LIMITS,
    METRICS,
    REFERENCE_LIMITS,
    RESOLUTION_FACTORS,
    classing,
    component_steps,
    resolution,
)

FORMAT = "fsdecouple.certificate"
FORMAT_VERSION = 1
# settings that decide what a calibration file's numbers mean: a set read with
# others than the model's is not the set the model was fitted on
READING_KEYS = ("sensor", "full_scale", "columns", "scale", "csv", "units", "components",
                "outputs", "zero")


def reading_differences(mine: Settings, theirs: Settings, skip=()) -> list[str]:
    """The keys of :data:`READING_KEYS` (but ``skip``) on which two settings would read a
    calibration set's numbers otherwise."""
    a, b = mine.to_dict(), theirs.to_dict()
    return [k for k in READING_KEYS if k not in skip and a.get(k) != b.get(k)]


def check_matches(model: CouplingErrorModel, calib: CalibrationSet, source: str,
                  settings: Settings | None = None) -> None:
    """Refuse a calibration set, or a config, that is not the one the model was fitted on.

    The set must hold the very files of the model's provenance, by name *and* by
    SHA-256 (a copy of ``rep1.csv`` saved as ``rep7.csv`` has rep1's digest but is
    a seventh repetition), and the same repetition labels.  A config must read the
    set as the model did (:data:`READING_KEYS`); a key it leaves unsaid that fit
    chose itself (``zero: fit`` on sweeps out and back) is the model's choice.
    """
    fitted = [(Path(f["path"]).name, f["sha256"]) for f in model.provenance.get("files", [])]
    given = [(Path(path).name, digest) for path, digest in calib.files]
    if fitted and sorted(fitted) != sorted(given):
        raise InputError(f"{calib.source}: does not match the model file {source}: "
                         f"{_first_difference(fitted, given)}")
    left_out = sorted(excluded_lines(model.provenance.get("excluded")))
    if left_out != sorted(excluded_lines(calib.excluded)):
        raise InputError(f"{calib.source}: does not match the model file {source}: its fit left "
                         f"out {', '.join(left_out) or 'no line'}, the set as read "
                         f"{', '.join(excluded_lines(calib.excluded)) or 'none'} (read it with "
                         "the model's exclusions: excluded_lines of its provenance)")
    reps = model.report.repetitions if model.report is not None else []
    if reps and sorted(reps) != sorted(calib.repetitions):
        extra = sorted(set(calib.repetitions) - set(reps))
        missing = sorted(set(reps) - set(calib.repetitions))
        what = (f"it has repetition {extra[0]}, which the model was not fitted on" if extra
                else f"it lacks repetition {missing[0]}, which the model was fitted on")
        raise InputError(f"{calib.source}: does not match the model file {source}: {what}")
    if settings is not None:
        refuse_unused(settings, model.settings, "certificate")
        # zero unsaid: fit's own choice (rows, or fit on sweeps out and back)
        differ = reading_differences(settings, model.settings,
                                     skip=("zero",) if settings.zero is None else ())
        if differ:
            raise InputError(f"the config's {differ[0]} is not the model's ({source}): the set "
                             "would be read otherwise than it was fitted; use the model's own "
                             "settings (no -c) or the config it was fitted with")


def _first_difference(fitted: list[tuple[str, str]], given: list[tuple[str, str]]) -> str:
    """The first file of the set that is not the model's, said by name and digest."""
    by_name = dict(fitted)
    names_of = {}
    for name, digest in fitted:
        names_of.setdefault(digest, name)
    for name, digest in sorted(given):
        if by_name.get(name) == digest:
            continue
        if name in by_name:
            return f"{name} is not the file the model was fitted on under that name (SHA-256 differs)"
        if digest in names_of:
            return (f"{name} is not a file the model was fitted on: its content is "
                    f"{names_of[digest]}'s, under another name")
        return f"{name} is not a file the model was fitted on"
    seen = {n for n, _ in given}
    missing = sorted(n for n, _ in fitted if n not in seen) or sorted(n for n, _ in fitted)
    return f"the model was fitted on {missing[0]} too, which it lacks"


def _model_errors(model: CouplingErrorModel, axis: str, loads: np.ndarray, source: str) -> np.ndarray:
    data = (model.report.certificate or {}) if model.report is not None else {}
    steps = data.get("steps", {}).get(axis)
    if steps is None:
        from ..core.modelfile import why_no_certificate

        raise InputError(f"{source}: the model file has no certificate data "
                         f"({why_no_certificate(model)})")
    known = dict(zip(steps["load"], steps["model_error"], strict=True))
    missing = [f for f in loads.tolist() if f not in known]
    if missing:
        raise InputError(f"{source}: the model has no {axis} step at load {missing[0]:g}: the "
                         "calibration set is not the one it was fitted on")
    return np.array([known[f] for f in loads.tolist()])


def _pct(v: float) -> float:
    return float(v) * 100.0


def drift_fractions(drift: dict | None, percent: float | None, axis: str, loads: np.ndarray,
                    full_scale: float) -> tuple[np.ndarray, str | None]:
    """The relative change between calibrations at each step [fraction], and its source.

    ``drift``: a ``compare --json`` document (``fsdecouple.drift``): |F_old - F_new| /
    |L| at its calibrated steps of this component (interpolated over load between
    them; the larger where both calibrations have the load), or without steps its
    ``force_max_pct`` of full scale; ``percent``: the
    config's ``drift`` [%], for every step.  Neither: zeros and None.
    """
    if drift is not None:
        steps = [s for s in drift.get("en_steps") or [] if s.get("axis") == axis]
        if steps:
            largest: dict[float, float] = {}  # a load both calibrations have: the larger
            for s in steps:
                f = float(s["load"])
                largest[f] = max(largest.get(f, 0.0), abs(float(s["F_old"]) - float(s["F_new"])))
            at = np.array(sorted(largest))
            moved = np.interp(loads, at, [largest[f] for f in at])
            return moved / np.abs(loads), "compare --json (|F_old - F_new| at each step)"
        comp = (drift.get("components") or {}).get(axis) or {}
        if comp.get("force_max_pct") is not None:
            return (np.full(loads.size, comp["force_max_pct"] / 100.0 * full_scale) / np.abs(loads),
                    "compare --json (force_max_pct of full scale)")
    if percent is not None:
        return np.full(loads.size, percent / 100.0), "config drift"
    return np.zeros(loads.size), None


def _drift_stated(sources: dict[str, str | None], drift: dict | None,
                  percent: float | None) -> dict:
    """What the budget's drift term rests on, for the certificate to state: the sources
    (per component where they differ), the config's percentage where it is used, and the
    two model files a compare document compared where it is."""
    used = sorted({v for v in sources.values() if v is not None})
    out: dict[str, Any] = {"source": "; ".join(used) or None, "components": dict(sources)}
    if "config drift" in used:
        out["percent"] = percent
    if drift is not None and any(u != "config drift" for u in used):
        out["models"] = [str(m.get("model")) for m in (drift.get("old"), drift.get("new"))
                         if isinstance(m, dict) and m.get("model") is not None]
    return out


def check_drift_document(doc, source: str) -> dict:
    """A ``compare --json`` document, or one line naming ``source``."""
    if not isinstance(doc, dict) or doc.get("format") != "fsdecouple.drift":
        raise InputError(f"{source}: not the output of 'fsdecouple compare --json' (expected "
                         "\"format\": \"fsdecouple.drift\")")
    steps = doc.get("en_steps") or []
    if not isinstance(steps, list):
        raise InputError(f"{source}: en_steps: expected a list of steps")
    for s in steps:
        try:
            ok = all(np.isfinite(float(s[k])) for k in ("load", "F_old", "F_new")) \
                and s["load"] != 0 and np.isfinite(float(s["F_old"]) - float(s["F_new"])) \
                and isinstance(s.get("axis"), str)
        except (KeyError, TypeError, ValueError, AttributeError):
            ok = False
        if not ok:
            raise InputError(f"{source}: en_steps: each step needs an axis, a non-zero load and "
                             "finite F_old and F_new")
    components = doc.get("components") or {}
    if not isinstance(components, dict) or not all(isinstance(c, dict) for c in components.values()):
        raise InputError(f"{source}: components: expected an object per component")
    for axis, comp in components.items():
        pct = comp.get("force_max_pct")
        if pct is not None and not (isinstance(pct, int | float) and not isinstance(pct, bool)
                                    and np.isfinite(pct) and pct >= 0):
            raise InputError(f"{source}: components.{axis}.force_max_pct: expected a finite "
                             f"number >= 0, not {pct!r}")
    return doc


def check_drift_matches(doc: dict, model: CouplingErrorModel, source: str) -> dict:
    """``doc`` (a checked ``compare --json`` document) in the model's component names
    (ATI's ``tx`` as the model's ``mx``, as compare matches them), or one line refusing
    it: of another sensor, other components or another load unit than ``model``'s (its
    drift would be dropped or misread), or a change beyond MAX_FULL_SCALES full scales."""
    labels = model.layout.labels
    mine = {component_key(a): a for a in labels}
    components = {mine.get(component_key(str(k)), k): v for k, v in (doc.get("components") or {}).items()}
    steps = [{**st, "axis": mine.get(component_key(st["axis"]), st["axis"])}
             for st in doc.get("en_steps") or []]
    named = set(components) | {st["axis"] for st in steps}
    if not named & set(labels):
        raise InputError(f"{source}: its components ({', '.join(sorted(named)) or 'none'}) are "
                         f"not the model's ({', '.join(labels)}): the drift of another sensor")
    sensors = {str(m.get("sensor")) for m in (doc.get("old"), doc.get("new"))
               if isinstance(m, dict) and m.get("sensor") is not None}
    if sensors and model.settings.sensor not in sensors:
        raise InputError(f"{source}: compares sensor {' and '.join(sorted(sensors))}, not "
                         f"{model.settings.sensor}, the model's")
    unit = (doc.get("units") or {}).get("load") if isinstance(doc.get("units"), dict) else None
    if unit is not None and unit != model.settings.units.load:
        raise InputError(f"{source}: its forces are in {unit}, the model's in "
                         f"{model.settings.units.load}")
    fs = dict(zip(labels, model.settings.full_scale, strict=True))
    for axis, comp in components.items():
        if comp.get("force_max_pct") is not None and comp["force_max_pct"] > 100 * MAX_FULL_SCALES:
            raise InputError(f"{source}: components.{axis}.force_max_pct = {comp['force_max_pct']!r}: "
                             f"more than {MAX_FULL_SCALES:g} full scales")
    for st in steps:
        moved = abs(float(st["F_old"]) - float(st["F_new"]))
        if st["axis"] in fs and moved > MAX_FULL_SCALES * fs[st["axis"]]:
            raise InputError(f"{source}: en_steps: {st['axis']} at {st['load']!r}: F_old - F_new = "
                             f"{moved:g}, more than {MAX_FULL_SCALES:g} full scales")
    return {**doc, "components": components, "en_steps": steps}


def read_drift(path: str | Path) -> dict:
    """The ``compare --json`` output in file ``path`` (``certificate --drift``)."""
    import json

    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(f"{path}: cannot read ({err.__class__.__name__}): expected the output of "
                         "'fsdecouple compare --json'") from None
    try:
        doc = json.loads(text)
    except ValueError as err:
        raise InputError(f"{path}: not JSON ({err}): expected the output of "
                         "'fsdecouple compare --json'") from None
    return check_drift_document(doc, str(path))


def _at_reference_temperature(calib: CalibrationSet, model: CouplingErrorModel
                              ) -> tuple[CalibrationSet, str | None]:
    """``calib`` with outputs at T0 by the model's own temperature terms, as fit corrected
    it before every figure (issue 31), and the note that says so; else as it is.  The
    instrument is the sensor with its correction: b, b' and f_c of uncorrected outputs
    counted the drift the model removes, and the budget's temperature term again."""
    terms = getattr(model, "temperature", None)
    if terms is None or not terms.external or TEMPERATURE not in calib.points.columns \
            or getattr(calib, "temperature_fit", None) is not None:
        return calib, None
    from ..fitting.temperature import corrected_points

    points = corrected_points(calib, terms)
    return (replace(calib, points=points),
            f"figures of the outputs corrected to T0 = {terms.t0:g} {terms.unit} by the model's "
            "temperature terms (the instrument is the sensor with its correction); the budget's "
            "temperature term is what they leave")


def certificate(model: CouplingErrorModel, calib: CalibrationSet, *, source: str = "model",
                settings: Settings | None = None, drift: dict | None = None,
                drift_name: str = "the drift document") -> dict[str, Any]:
    """The certificate document of ``calib`` and the model fitted on it.

    ``settings``: the config's (``-c``), for the sensor's identity, reference,
    environment, creep column and drift; default: the model's own.  ``drift``: a
    ``compare --json`` document of this sensor's last two calibrations, for the
    budget's drift term (default: the config's ``drift``, else none), refused in one
    line naming ``drift_name`` where it is not this sensor's (:func:`check_drift_matches`).
    Refused if the set or the config do not match the model (:func:`check_matches`).
    """
    model.layout.one_output_each("certificate")
    check_matches(model, calib, source, settings)
    if drift is not None:
        drift = check_drift_matches(check_drift_document(drift, drift_name), model, drift_name)
    s = settings or model.settings
    lab, layout = s.lab, calib.layout
    calib, at_t0 = _at_reference_temperature(calib, model)
    times = creep_times(calib, s)
    records, budgets, classes, notes = [], [], [], []
    # about this run, not the sensor: printed, never on the certificate itself
    warnings = unused_warning(settings, model.settings, "certificate") if settings is not None else []
    if at_t0:
        notes.append(at_t0)
    if calib.excluded:
        notes.append(f"left out of every figure, as the model's fit left them out: "
                     f"{', '.join(excluded_lines(calib.excluded))}")
    n_reps = len(calib.repetitions)
    if n_reps < 2:
        notes.append(f"one repetition: b (reproducibility) and b' (repeatability) compare "
                     f"repetitions and need at least two; the set has {n_reps}, so no class "
                     "(ISO 376 classes need both) and no reproducibility in the budget")
    resolutions, sources, temperature = {}, {}, False
    for a, axis in enumerate(layout.labels):
        st = component_steps(calib, a, times)
        r = resolution(calib, a)
        resolutions[axis] = r
        u_model = _model_errors(model, axis, st.loads, source)
        w_t = temperature_term(calib, st)
        temperature |= w_t is not None
        d, sources[axis] = drift_fractions(drift, lab.drift, axis, st.loads, s.full_scale[a])
        b = budget(st, u_model, lab.reference_uncertainty, r, w_t or 0.0, d)
        for j, load in enumerate(st.loads.tolist()):
            for metric in METRICS:
                value = st.figures[metric][j]
                if np.isfinite(value):
                    records.append({"axis": axis, "load": load, "metric": metric, "value": float(value)})
            records.append({"axis": axis, "load": load, "metric": "U", "value": float(b["U"][j])})
            budgets.append({"axis": axis, "load": load,
                            **{c: _pct(b[c][j]) for c in (*CONTRIBUTIONS, "w_c", "W")},
                            "U": float(b["U"][j])})
        for sign, c in classing(st, s.full_scale[a], r, lab.reference_uncertainty).items():
            classes.append({"axis": axis, "sign": sign, **c})
    for metric, why in (("f_0", "no sweep reads zero at both its start and its end"),
                        ("v", "no sweep loads up and then down through the same steps"),
                        ("c", "no creep column in the config (creep: {column: ...})" if times is None
                         else "no sweep holds its largest load with readings 270 s apart")):
        if not any(r["metric"] == metric for r in records):
            notes.append(f"{metric}: absent, {why}; not classed")
    if not temperature:
        notes.append("temperature: the calibration has no temperature column; its budget term is 0")
    stated = _drift_stated(sources, drift, lab.drift)
    bare = [axis for axis, v in sources.items() if v is None]
    if drift is None and stated["source"] is None:
        notes.append("drift: no compare document and no config drift; the "
                     "budget's drift between calibrations is 0")
    elif bare:
        notes.append(f"drift: the compare document gives none of {', '.join(bare)}, and the "
                     "config states none; there the budget's drift between calibrations is 0")
    return {
        "format": FORMAT, "format_version": FORMAT_VERSION, "fsdecouple_version": __version__,
        "date": datetime.now(UTC).date().isoformat(),
        "sensor": s.sensor, "serial": lab.serial,
        "reference": {"description": lab.reference, "uncertainty_percent_k2": lab.reference_uncertainty},
        "environment": dict(lab.environment),
        "units": {"load": s.load_unit, "output": s.output_unit,
                  "loads": {axis: s.units.load_of(a) for a, axis in enumerate(layout.labels)}},
        "model": {"file": source, "created": model.created, "method": model.method},
        "calibration": {"source": calib.source, "repetitions": calib.repetitions,
                        "files": [{"path": p, "sha256": h} for p, h in calib.files]},
        "full_scale": dict(zip(layout.labels, s.full_scale, strict=True)),
        "resolution": resolutions,
        "records": records,
        "classes": classes,
        "class_limits": {"source": "ISO 376:2011, Table 2",
                         "limits_percent": {c: lim for c, lim in CLASS_LIMITS},
                         "reference_source": "ISO 376:2011, Table 3",
                         "reference_limits_percent_k2": dict(REFERENCE_LIMITS),
                         "lower_limit_resolutions": dict(RESOLUTION_FACTORS),
                         "from_fraction_of_full_scale": CLASS_FROM},
        "budget": budgets,
        "budget_sources": dict(SOURCES),
        "drift_source": stated["source"],
        "drift": stated,
        "coverage_factor": 2,
        "notes": notes,
        "warnings": warnings,
        # the model's temperature terms (issue 31): the outputs were corrected to T0 by them
        **({"temperature": model.temperature.to_dict(layout.outputs)}
           if getattr(model, "temperature", None) is not None else {}),
    }
