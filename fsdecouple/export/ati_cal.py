"""ATI calibration files (``.cal`` XML) out: a linear six-component model for ATIDAQ.

The file holds the model's matrix C (6 x NumGages) as ATI's DAQ library
(ATIDAQ, ftconfig.c) reads it back: six ``Axis`` rows named Fx .. Tz with
``values`` = C's row and ``scale`` = 1, a ``BasicTransform`` of zeros (so the
working matrix is C itself), ``max`` = the full scale, and ``UserAxis`` rows equal
to the ``Axis`` rows (consistent by construction).  A model with a frame (config
``frame:`` or ``rotation:``) has it folded in: C' = T C, so ATIDAQ's forces are
``apply``'s.  Temperature terms become ``BiasSlope`` = -b, ``GainSlope`` = -g and
``Thermistor`` = T0 (core/temperature.py), the temperature output the last channel; a
fitted model's temperature column (``external``) becomes the thermistor channel after the
gauges, read by ATIDAQ unscaled, so in the model's own unit (degC).

Outputs in mV or uV are converted to the volts ATIDAQ reads (C x 1e3, x 1e6).
A nonlinear (svr) model is refused unless ``linear_part``: then its omega matrix
(eq. 2: f_a = u_a / k_a, or v = P u for M > N outputs) is written, and
:func:`linear_part_loss` says what that loses on the model's own calibration span.
"""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from ..errors import InputError, printable
from ..files.outputs import atomic_write
from ..units import unit_key

AXIS_NAMES = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")
MAX_GAUGES = 8  # ATIDAQ's MAX_GAUGES
ATI_FORCE = {"N": "N", "kN": "kN", "lbf": "lbf", "klbf": "klbf", "kgf": "kg", "gf": "g"}
ATI_TORQUE = {"nm": "N-m", "nmm": "N-mm", "lbfin": "lbf-in", "lbfft": "lbf-ft", "kgfcm": "kg-cm",
              "knm": "kN-m"}
DIST_OF_TORQUE = {"N-m": "m", "N-mm": "mm", "lbf-in": "in", "lbf-ft": "ft", "kg-cm": "cm",
                  "kN-m": "m"}
VOLTS = {"V": 1.0, "mV": 1e-3, "uV": 1e-6}  # one output unit in volts
SWEEP_POINTS = 41  # per component, over its calibrated range (linear_part_loss)


def _units(model, source: str) -> tuple[str, str]:
    units = model.settings.units
    forces = {units.load_of(a) for a in range(3)}
    torques = {units.load_of(a) for a in range(3, 6)}
    if len(forces) != 1 or len(torques) != 1:
        raise InputError(f"{source}: a .cal has one force unit and one torque unit; the model's "
                         f"components are in {', '.join(sorted(forces | torques))}")
    force, torque = forces.pop(), torques.pop()
    if force not in ATI_FORCE:
        raise InputError(f"{source}: force unit {force!r} has no ATIDAQ name (known: "
                         f"{', '.join(ATI_FORCE)}); the first three components must be forces")
    if unit_key(torque) not in ATI_TORQUE:
        raise InputError(f"{source}: torque unit {torque!r} has no ATIDAQ name (N·m, N·mm, lbf·in, "
                         "lbf·ft, kgf·cm, kN·m); the last three components must be moments")
    return ATI_FORCE[force], ATI_TORQUE[unit_key(torque)]


def omega_matrix(model) -> np.ndarray:
    """The omega matrix (eq. 2 inverted, eq. 13 form) of any model: diag(1/k) P, N x M."""
    p = np.eye(model.n_components) if model.projection is None else np.asarray(model.projection)
    return p / np.asarray(model.k, dtype=float)[:, None]


def linear_part_loss(model, c: np.ndarray) -> np.ndarray:
    """Per component, the largest |f_model - C u| on the model's own calibration [% F.S.].

    The points are the model's single-component sweeps as eqs. (1)-(4) describe them:
    for each component b, prime outputs p_b over its calibrated range and, on every
    other output a, the coupling error element chi_ab(p_b) (M > N: outputs u = P^+ v).
    """
    n = model.n_components
    rng = model.calibrated_range
    rows = []
    for b in range(n):
        p = np.linspace(rng[b, 0], rng[b, 1], SWEEP_POINTS)
        v = np.zeros((p.size, n))
        v[:, b] = p
        for ch in model.chi.values():
            if ch.input_axis == b and ch.output_axis != b:
                v[:, ch.output_axis] += ch(p)
        rows.append(v)
    v = np.concatenate(rows)
    u = v if model.projection is None else v @ np.linalg.pinv(model.projection).T
    f_model = model.decouple(u, rotate=False, exact=True)
    fs = np.asarray(model.settings.full_scale, dtype=float)
    return 100.0 * np.nanmax(np.abs(f_model - u @ c.T), axis=0) / fs


def plan_cal(model, source: str = "model", *, linear_part: bool = False) -> dict[str, Any]:
    """What the .cal will hold: matrix, units, slopes, and the notes ``export`` prints."""
    notes: list[str] = []
    lost = None
    if model.n_components != 6:
        raise InputError(f"{source}: a .cal for ATIDAQ holds six axes Fx .. Tz; this model has "
                         f"{model.n_components} components ({', '.join(model.layout.labels)})")
    if model.method == "linear":
        c = np.asarray(model.matrix, dtype=float)
        if linear_part:
            notes.append("--linear-part: the model is linear already; its matrix is written whole")
    elif not linear_part:
        raise InputError(f"{source}: a {model.method} model (eq. 11 with its chi) is not linear and "
                         "a .cal holds a matrix; export --linear-part writes its omega matrix and "
                         "says what that loses")
    else:
        c = omega_matrix(model)
        lost = linear_part_loss(model, c)
        notes.append("--linear-part: wrote the omega matrix (eq. 2), without the chi; lost on the "
                     "model's own calibration span: " + ", ".join(
                         f"{a} {v:.3g} %" for a, v in zip(model.layout.labels, lost, strict=True))
                     + " of full scale")
    force, torque = _units(model, source)
    out_unit = model.settings.units.output
    if {model.settings.units.output_of(i) for i in range(model.n_outputs)} != {out_unit} \
            or out_unit not in VOLTS:
        raise InputError(f"{source}: outputs in {out_unit}; ATIDAQ reads gauges in volts (a model in "
                         f"{', '.join(VOLTS)} is converted)")
    temp = model.temperature
    gauges = [i for i in range(model.n_outputs) if temp is None or i != temp.channel]
    if len(gauges) > MAX_GAUGES:
        raise InputError(f"{source}: {len(gauges)} outputs; ATIDAQ reads at most {MAX_GAUGES} gauges")
    if temp is not None and temp.external:  # fitted (fitting/temperature.py), T in degC
        # ATIDAQ reads the thermistor channel after the gauges as it is, unscaled: the same
        # correction when that channel carries the temperature in the model's unit
        notes.append(f"the temperature terms are the fit's, in {temp.unit}: ATIDAQ's thermistor "
                     f"channel (after the {len(gauges)} gauges) must carry the temperature in "
                     f"{temp.unit}; a .cal has no place for the calibrated span")
    elif temp is not None and temp.channel != model.n_outputs - 1:
        raise InputError(f"{source}: the temperature output is not the last; ATIDAQ reads the "
                         "thermistor after the gauges")
    rotation = model.rotation
    if rotation is not None:
        c = np.asarray(rotation, dtype=float) @ c
        notes.append("the model's frame transform is folded into the matrix (forces as apply "
                     "writes them)")
    to_volts = VOLTS[out_unit]
    if to_volts != 1.0:
        notes.append(f"outputs converted from {out_unit} to V (matrix x {1 / to_volts:g})")
    c = c[:, gauges] / to_volts
    plan: dict[str, Any] = {"matrix": c, "force_units": force, "torque_units": torque,
                            "max": [float(v) for v in model.settings.full_scale], "notes": notes,
                            "lost_pct": None if lost is None else
                            dict(zip(model.layout.labels, map(float, lost), strict=True))}
    ati = model.provenance.get("ati") or {}
    cal_attrs = dict(ati.get("calibration") or {})
    plan["dist_units"] = cal_attrs.get("DistUnits") if cal_attrs.get("TorqueUnits") == torque \
        and cal_attrs.get("DistUnits") else DIST_OF_TORQUE[torque]
    if temp is not None:
        plan["bias_slope"] = [-float(temp.b[i]) * to_volts for i in gauges]  # ATI's BS = -b [V/unit]
        plan["gain_slope"] = [-float(temp.g[i]) for i in gauges]  # GS = -g
        plan["thermistor"] = float(temp.t0)
        if temp.unit != "V" and not temp.external:
            notes.append(f"the temperature channel is in {temp.unit}: ATIDAQ's thermistor channel "
                         f"must then read {temp.unit} too")
    sensor = {"Serial": model.settings.sensor, "BodyStyle": "fsdecouple", "Family": "DAQ",
              **(ati.get("sensor") or {})}
    sensor.update(NumGages=str(len(gauges)), CalFileVersion=sensor.get("CalFileVersion", "1.0"))
    date = (model.created or datetime.now(UTC).isoformat())[:10]
    cal_attrs.update(PartNumber=cal_attrs.get("PartNumber", model.settings.sensor),
                     CalDate=cal_attrs.get("CalDate", date), ForceUnits=force, TorqueUnits=torque,
                     DistUnits=plan["dist_units"])
    cal_attrs.pop("AngleUnits", None)  # BasicTransform is all zeros
    plan["sensor"], plan["calibration"] = sensor, cal_attrs
    return plan


def _attrs(d: dict[str, str]) -> str:
    return "".join(f" {k}={quoteattr(str(v))}" for k, v in d.items())


def _row(values) -> str:
    return " " + " ".join(repr(float(v)) for v in values) + " "


def cal_text(plan: dict[str, Any]) -> str:
    """The .cal XML of :func:`plan_cal`."""
    c = plan["matrix"]
    lines = ['<?xml version="1.0" encoding="utf-8"?>',
             "<!-- Written by fsdecouple export: Axis rows are the working matrix (scale 1, no   -->",
             "<!-- basic transform); UserAxis rows are the same matrix.                          -->",
             f"<FTSensor{_attrs(plan['sensor'])}>", f"\t<Calibration{_attrs(plan['calibration'])}>"]
    for i, name in enumerate(AXIS_NAMES):
        lines.append(f'\t\t<Axis Name="{name}" values="{_row(c[i])}" max="{plan["max"][i]!r}" '
                     'scale="1"/>')
    lines.append('\t\t<BasicTransform Dx="0" Dy="0" Dz="0" Rx="0" Ry="0" Rz="0"/>')
    if "bias_slope" in plan:
        lines += [f'\t\t<BiasSlope values="{_row(plan["bias_slope"])}"/>',
                  f'\t\t<GainSlope values="{_row(plan["gain_slope"])}"/>',
                  f'\t\t<Thermistor value="{plan["thermistor"]!r}"/>']
    for i, name in enumerate(AXIS_NAMES):
        lines.append(f'\t\t<UserAxis Name="{name}" values="{_row(c[i])}" max="{plan["max"][i]!r}"/>')
    lines += ["\t</Calibration>", "</FTSensor>", ""]
    return "\r\n".join(lines)


def export_cal(model, path: str | Path, *, source: str = "model", linear_part: bool = False,
               force: bool = False) -> dict[str, Any]:
    """Write ``model`` as an ATI calibration file at ``path``, atomically.

    Returns ``{"path", "num_gages", "temperature", "lost_pct", "notes", "lines"}`` (``lines``:
    what ``export`` prints); ``lost_pct``
    (per component, % F.S.) only for ``linear_part`` of a nonlinear model.
    """
    plan = plan_cal(model, source, linear_part=linear_part)
    text = cal_text(plan)
    with atomic_write(path, "w", force=force) as fh:
        fh.write(text)
    return {"path": str(path), "num_gages": int(plan["matrix"].shape[1]),
            "temperature": "bias_slope" in plan, "lost_pct": plan["lost_pct"],
            "notes": plan["notes"],
            "lines": [f"wrote {printable(path)}: ATI calibration, 6 axes from "
                      f"{plan['matrix'].shape[1]} gauges, {plan['force_units']} and "
                      f"{plan['torque_units']}" + (", temperature slopes" if "bias_slope" in plan
                                                   else ""), *plan["notes"]]}
