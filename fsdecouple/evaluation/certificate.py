"""The calibration certificate as plain data: ISO 376 figures, class and uncertainty budget.

:func:`certificate` reads a calibration set against the model fitted on it and
returns the ``fsdecouple.certificate`` document: ``records`` ``[{axis, load, metric,
value}]`` (``b``, ``b_prime``, ``f_c``, ``f_0``, ``v`` [%], ``U`` [load unit], one per
component, non-zero load step of its own sweeps and metric; figures a set cannot give
are absent and ``notes`` say why), a ``classes`` list, and the ``budget`` of every
step (:mod:`fsdecouple.evaluation.budget`).
"""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from ..config import Settings
from ..core.model import CouplingErrorModel
from ..data.calibration import CalibrationSet
from ..errors import InputError
from .budget import CONTRIBUTIONS, budget
from .iso376 import CLASS_FROM, CLASS_LIMITS, METRICS, classify, component_steps, resolution

FORMAT = "fsdecouple.certificate"
FORMAT_VERSION = 1
# settings that decide what a calibration file's numbers mean: a set read with
# others than the model's is not the set the model was fitted on
READING_KEYS = ("sensor", "full_scale", "columns", "scale", "csv", "units", "components",
                "outputs", "zero")


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
    reps = model.report.repetitions if model.report is not None else []
    if reps and sorted(reps) != sorted(calib.repetitions):
        extra = sorted(set(calib.repetitions) - set(reps))
        missing = sorted(set(reps) - set(calib.repetitions))
        what = (f"it has repetition {extra[0]}, which the model was not fitted on" if extra
                else f"it lacks repetition {missing[0]}, which the model was fitted on")
        raise InputError(f"{calib.source}: does not match the model file {source}: {what}")
    if settings is not None:
        mine, theirs = settings.to_dict(), model.settings.to_dict()
        for key in READING_KEYS:
            if key == "zero" and settings.zero is None:
                continue  # unsaid: fit's own choice (rows, or fit on sweeps out and back)
            if mine.get(key) != theirs.get(key):
                raise InputError(f"the config's {key} is not the model's ({source}): the set would "
                                 "be read otherwise than it was fitted; use the model's own "
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
        raise InputError(f"{source}: the model file has no certificate data (fitted by an older "
                         "fsdecouple, or with --no-verdict): refit it")
    known = dict(zip(steps["load"], steps["model_error"], strict=True))
    missing = [f for f in loads.tolist() if f not in known]
    if missing:
        raise InputError(f"{source}: the model has no {axis} step at load {missing[0]:g}: the "
                         "calibration set is not the one it was fitted on")
    return np.array([known[f] for f in loads.tolist()])


def _pct(v: float) -> float:
    return float(v) * 100.0


def certificate(model: CouplingErrorModel, calib: CalibrationSet, *, source: str = "model",
                settings: Settings | None = None) -> dict[str, Any]:
    """The certificate document of ``calib`` and the model fitted on it.

    ``settings``: the config's (``-c``), for the sensor's identity, reference and
    environment; default: the model's own.  Refused if the set or the config do not
    match the model (:func:`check_matches`).
    """
    model.layout.one_output_each("certificate")
    check_matches(model, calib, source, settings)
    s = settings or model.settings
    lab, layout = s.lab, calib.layout
    records, budgets, classes, notes = [], [], [], []
    n_reps = len(calib.repetitions)
    if n_reps < 2:
        notes.append(f"one repetition: b (reproducibility) and b' (repeatability) compare "
                     f"repetitions and need at least two; the set has {n_reps}, so no class "
                     "(ISO 376 classes need both) and no reproducibility in the budget")
    resolutions = {}
    for a, axis in enumerate(layout.labels):
        st = component_steps(calib, a)
        r = resolution(calib, a)
        resolutions[axis] = r
        u_model = _model_errors(model, axis, st.loads, source)
        b = budget(st, u_model, lab.reference_uncertainty, r)
        for j, load in enumerate(st.loads.tolist()):
            for metric in METRICS:
                value = st.figures[metric][j]
                if np.isfinite(value):
                    records.append({"axis": axis, "load": load, "metric": metric, "value": float(value)})
            records.append({"axis": axis, "load": load, "metric": "U", "value": float(b["U"][j])})
            budgets.append({"axis": axis, "load": load,
                            **{c: _pct(b[c][j]) for c in (*CONTRIBUTIONS, "w_c", "W")},
                            "U": float(b["U"][j])})
        for sign, cls in classify(st, s.full_scale[a]).items():
            classes.append({"axis": axis, "sign": sign, "class": cls})
    for metric, why in (("f_0", "no sweep reads zero at both its start and its end"),
                        ("v", "no sweep loads up and then down through the same steps")):
        if not any(r["metric"] == metric for r in records):
            notes.append(f"{metric}: absent, {why}")
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
        "class_limits": {"source": "ISO 376:2011, Table 2", "from_fraction_of_full_scale": CLASS_FROM,
                         "limits_percent": {c: lim for c, lim in CLASS_LIMITS}},
        "budget": budgets,
        "coverage_factor": 2,
        "notes": notes,
    }
