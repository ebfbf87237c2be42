"""Validation of a fitted model on an independent single-axis set (``fsdecouple validate``).

The set is read exactly like a calibration set (sweeps, zero rows, known loads;
each sweep zero-corrected by its own zero-load rows), decoupled by eq. (11)
(``model``), by the least-squares calibration matrix fitted on the model's own
calibration (``linear``: the model file's ``matrix``, or one fitted on ``calib``)
and by omega^-1 alone (``initial``), and scored per loaded axis:

* ``gamma``: the interference error of eq. (12) on that axis's single-load sweep
  points (a combined-load point, which loads several components at once, has no
  off-axis error to measure: it is scored by the errors below only);
* ``max_error``, ``rms_error``: over that axis's sweep points p and every
  component c, the error e(p, c) = |f_c(p) - F_c(p)| / F_c(FS) of the decoupled
  force against the known load, as a fraction of that component's full scale;
  the largest e, and the root of the mean of e^2.  ``value_load_unit`` is the
  same fraction on the largest full scale of the components,
  ``value * max_c F_c(FS)``, so it bounds every component's absolute error.

Each figure is given apart for the points whose prime outputs all lie in the
model's calibrated range (widened as ``apply`` widens it, by
:data:`fsdecouple.core.model.RANGE_MARGIN` of the span) and for the others, which the
model extrapolates.  Zero-load rows are points at 0 load, as in :mod:`metrics`, but
a group without a loaded point has no figure (``value`` None): zero rows alone
would score a perfect 0.  Each record's ``n`` is the number of points its value
is computed over (0 for None).
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from ..config import Settings
from ..core.metrics import check_max_gamma, interference_error
from ..core.model import FORCE_LIMIT, CouplingErrorModel
from ..core.modelfile import content_digest, load_model, model_to_dict
from ..errors import InputError, printable, where
from ..files.outputs import atomic_write, check_output, refuse_overwriting_input
from ..schema import refuse_unused, unused_warning

FORMAT = "fsdecouple.validation"
FORMAT_VERSION = 1
METHODS = ("model", "linear", "initial")
METRICS = ("gamma", "max_error", "rms_error")
RANGES = ("calibrated", "extrapolated")
# calibration warnings that do not apply to a validation set, which may use other
# loads than the calibration and go beyond its full scale on purpose
_NOT_FOR_VALIDATION = ("uses a different load grid than repetition", "loads reach")


def in_calibrated_range(model: CouplingErrorModel, u: np.ndarray) -> np.ndarray:
    """Rows whose outputs all lie in the calibrated range, widened as ``apply`` widens it
    (M > N outputs: their least-squares loads v = P u, fitting/gauges.py)."""
    lo, hi = model.extrapolation_limits().T
    v = model.project(u)
    return ((v >= lo) & (v <= hi)).all(axis=1)


def force_errors(forces: np.ndarray, loads: np.ndarray, full_scale) -> dict[str, float]:
    """Max and RMS of |f_c - F_c| / F_c(FS) over every point and component."""
    e = np.abs(np.asarray(forces) - np.asarray(loads)) / np.asarray(full_scale, dtype=float)
    return {"max_error": float(e.max()), "rms_error": float(np.sqrt(np.mean(e * e)))}


def validate(
    model: CouplingErrorModel | str | Path,
    set_path: str | Path,
    settings: Settings | None = None,
    *,
    max_gamma: float | None = None,
    output: str | Path | None = None,
    force: bool = False,
    inputs=(),
    calib: str | Path | None = None,
) -> dict[str, Any]:
    """Score ``model`` on the independent single-axis set ``set_path``.

    Parameters
    ----------
    model : CouplingErrorModel or path
        The fitted model, or its model file.
    set_path : path
        The validation set, a directory or CSV in calibration format.  It may hold
        fewer repetitions than ``min_repetitions`` and use other loads than the
        calibration.  A row loading two components at once (a combined load) is
        scored by ``max_error`` and ``rms_error`` of its labelled sweep and left
        out of ``gamma`` (eq. 12 needs single loads).
    settings : Settings, optional
        Columns, scales, full scale and units of the set; default: the model's.
    max_gamma : float, optional
        Gate: the model's worst gamma on calibrated points must not exceed this
        fraction (extrapolated points do not gate).
    calib : path, optional
        The model's calibration set, to fit the least-squares matrix of the
        ``linear`` records on; needed only for a model file without a stored
        ``matrix`` (those fitted before it was kept).
    output : path, optional
        Also write the document there, atomically; never over an input file
        (the model, the set's files, ``inputs``) and only with ``force`` over
        another existing file.

    Returns
    -------
    dict
        The validation document (docs/validate.md: its keys and records).
    """
    from ..data.calibration import load_calibration

    check_max_gamma(max_gamma)
    if output is not None:
        check_output(output, force=force)
    model_path = Path(model) if isinstance(model, str | Path) else None
    if model_path is not None:
        model = load_model(model_path)
    if settings is not None:
        refuse_unused(settings, model.settings, "validate")
    settings = settings or model.settings
    terms = getattr(model, "temperature", None)
    if terms is not None and not terms.external:  # an ATI thermistor (core/temperature.py)
        raise InputError("validate: the model corrects its outputs for temperature, which a set "
                         "zero-corrected sweep by sweep does not carry; apply it to a log instead")
    if settings.layout != model.layout:
        raise InputError(f"the config names components {', '.join(settings.layout.loads)}, the "
                         f"model {', '.join(model.layout.loads)}; use the calibration's config")
    if replace(settings.units, temperature=None) != replace(model.settings.units, temperature=None):
        set_u, model_u = settings.units, model.settings.units  # 'N / N·m' where mixed
        raise InputError(f"the config reads the set with loads in {set_u.load}, outputs in "
                         f"{set_u.output}; the model was calibrated with loads in {model_u.load}, "
                         f"outputs in {model_u.output}: use the calibration's config")
    cs = load_calibration(set_path, replace(settings, min_repetitions=1), combined=True)
    if terms is not None:  # a fitted model's terms: the set's outputs at T0 by them
        cs = _at_t0(cs, terms, set_path)
    refuse_meaningless(cs, model)
    points = cs.points
    u, loads = cs.voltages.astype(float), cs.forces.astype(float)
    single = (loads != 0.0).sum(axis=1) <= 1
    loaded = (loads != 0.0).any(axis=1)
    warnings = [w for w in cs.warnings if not any(x in w for x in _NOT_FOR_VALIDATION)]
    warnings += unused_warning(settings, model.settings, "validate")
    forces = {"model": model.decouple(u, rotate=False)}
    matrix, calib_files = (model.matrix, []) if model.matrix is not None else \
        _matrix_of(calib, model)
    if model.matrix is not None and calib is not None:  # never ignored in silence
        warnings.append(f"calibration {printable(calib)}: not read; the model file holds the "
                        "least-squares matrix of its own calibration")
    if matrix is not None:
        forces["linear"] = u @ np.asarray(matrix).T
    else:
        warnings.append("the model file holds no least-squares matrix (fitted before "
                        "fsdecouple kept it): give its calibration set to set the "
                        "matrix fitted on it beside the model")
    forces["initial"] = model.initial_forces(u)
    if getattr(model, "imported", False):  # a factory matrix: its own f = C u, nothing beside
        forces = {"model": forces["model"]}
    inside = in_calibrated_range(model, u)
    axis_of = points["axis"].to_numpy()
    fs = np.asarray(settings.full_scale, dtype=float)
    units = settings.units.loads or None
    records = []
    if not single.all():
        warnings.append(f"{int((~single).sum())} combined-load points (several components "
                        "loaded at once): scored by max and RMS error, not gamma")
    for a, axis in enumerate(settings.layout.labels):
        on_axis = axis_of == axis
        outside = int((on_axis & ~inside).sum())
        if outside:
            warnings.append(
                f"{outside} of {int(on_axis.sum())} {axis}-sweep points have an output outside "
                "the calibrated range; reported apart as 'extrapolated'"
            )
        for rng, sel in (("calibrated", on_axis & inside), ("extrapolated", on_axis & ~inside)):
            if not sel.any():
                continue
            # no loaded point, no figure: zero rows alone would score a perfect 0
            has_load = bool((sel & loaded).any())
            gsel = sel & single
            for method in METHODS:
                if method not in forces:
                    continue
                key = {"method": method, "axis": axis, "range": rng}
                if gsel.any():
                    scored = has_load and bool((gsel & loaded).any())
                    value = (interference_error(forces[method][gsel], a, fs if units else fs[a],
                                                units) if scored else None)
                    records.append({**key, "metric": "gamma", "value": value,
                                    "n": int(gsel.sum()) if scored else 0})
                errors = force_errors(forces[method][sel], loads[sel], fs) if has_load else \
                    dict.fromkeys(("max_error", "rms_error"))
                for metric, value in errors.items():
                    records.append({**key, "metric": metric, "value": value,
                                    "value_load_unit": None if value is None else
                                    value * float(fs.max()),
                                    "n": int(sel.sum()) if has_load else 0})
    records.sort(key=lambda r: (r["axis"], METHODS.index(r["method"]),
                                RANGES.index(r["range"]), METRICS.index(r["metric"])))
    doc = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "fsdecouple_version": __version__,
        "model": None if model_path is None else str(model_path),
        "model_digest": content_digest(model_to_dict(model)),
        "set": {"path": str(set_path), "files": [{"path": p, "sha256": h} for p, h in cs.files],
                "points": len(points)},
        "units": {"load": getattr(settings, "load_unit", "N"),
                  "output": getattr(settings, "output_unit", "V")},
        "records": records,
        # what the "initial" rows decouple by: omega^-1 alone, or M > N gauges' P u; an
        # imported factory matrix (its thermistor an extra output) has no initial rows
        "initial": (None if getattr(model, "imported", False) else
                    "f = P u" if model.layout.overdetermined else "f = u / k"),
        "gate": _gate(records, max_gamma),
        "warnings": warnings,
    }
    if terms is not None:  # the model's temperature terms, by which the set was corrected
        doc["temperature"] = terms.to_dict(model.layout.outputs)
    if output is not None:
        used = [*([model_path] if model_path is not None else []), *(p for p, _ in cs.files),
                *calib_files, *inputs]
        refuse_overwriting_input(output, used)
        with atomic_write(output, force=force) as fh:
            fh.write(dumps(doc) + "\n")
    return doc


def refuse_meaningless(cs, model: CouplingErrorModel) -> None:
    """A load or output beyond FORCE_LIMIT x the model's full scale is no measurement (1e308
    in a cell, loads in the wrong unit): its errors would overflow to inf, which no JSON
    holds.  Refused, naming its file, row and column, as apply gives it no forces."""
    layout, p = model.layout, cs.points
    for cols, scale in ((layout.loads, model.settings.full_scale),
                        (layout.outputs, model.full_scale_output)):
        values = p[list(cols)].to_numpy(dtype=float)
        bound = FORCE_LIMIT * float(np.max(np.abs(scale)))
        bad = np.argwhere(~(np.abs(values) <= bound))
        if len(bad):
            i, j = bad[0]
            raise InputError(f"{where(p['file'].iat[i], int(p['row'].iat[i]), cols[j])}: "
                             f"{values[i, j]:.6g} is beyond {FORCE_LIMIT:g} x the model's full "
                             f"scale ({np.max(np.abs(scale)):.6g}): check the set's units")


def _gate(records, max_gamma: float | None) -> dict[str, Any] | None:
    """The --max-gamma gate: the model's worst gamma over calibrated points."""
    if max_gamma is None:
        return None
    gammas = [r["value"] for r in records if r["value"] is not None
              and (r["method"], r["metric"], r["range"]) == ("model", "gamma", "calibrated")]
    worst = max(gammas) if gammas else None
    # no calibrated point at all is nothing to pass on
    return {"max_gamma": max_gamma, "worst": worst, "passed": worst is not None and worst <= max_gamma}


def _matrix_of(calib, model: CouplingErrorModel) -> tuple[np.ndarray | None, list[str]]:
    """The least-squares matrix fitted on ``calib`` read with the model's settings (None
    without ``calib``), and the files read."""
    if calib is None:
        return None, []
    from ..data.calibration import load_calibration
    from ..fitting.linear import fit_calibration_matrix

    cs = load_calibration(calib, model.settings)
    return fit_calibration_matrix(cs.voltages, cs.forces).C, [p for p, _ in cs.files]


def dumps(doc: dict[str, Any]) -> str:
    """The document as written by ``-o`` and printed by ``--json``."""
    return json.dumps(doc, indent=1, sort_keys=True, allow_nan=False)


def _at_t0(cs, terms, set_path):
    """The set's outputs corrected to T0 by the model's temperature terms, sweep by sweep
    (fitting/temperature.py); a set without the temperature column is refused."""
    from ..fitting.temperature import corrected_points

    if "temperature" not in cs.points.columns:
        raise InputError(f"{printable(set_path)}: no temperature column mapped (columns: "
                         "{temperature: ...}), which the model corrects for; use the "
                         "calibration's config")
    return replace(cs, points=corrected_points(cs, terms))
