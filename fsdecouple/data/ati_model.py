"""An ATI calibration file as a model: ``fsdecouple import FILE.cal -o model.json``.

:func:`import_cal` turns what :mod:`fsdecouple.data.ati_cal` reads into a ``linear``
:class:`~fsdecouple.core.model.CouplingErrorModel` that decouples as ATIDAQ does:

* outputs ``g0 .. g{NumGages-1}`` in the file's gauge order, ``thermistor`` last when
  the file compensates temperature;
* components named after the ``Axis`` rows in lower case (``fx fy fz tx ty tz``), in
  the file's force and torque units, full scale from ``max``;
* ``matrix`` = ``projection`` = W, the working matrix (a zero column for the
  thermistor), k = 1 and no chi: v = P u are the forces, and their range is +-max;
* ``temperature``: b = -BiasSlope, g = -GainSlope, T0 = Thermistor
  (:mod:`fsdecouple.core.temperature`), with the thermistor as the temperature.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError, excerpt, printable
from .ati_cal import (
    FORCE_UNITS,
    THERMISTOR,
    TORQUE_UNITS,
    TRANSFORM_KEYS,
    AtiCalibration,
    read_cal,
)


def import_cal(path: str | Path, index: int = 1, frame: Any = None, frame_source: str = "config"):
    """The linear model of an ATI calibration file (module docstring).

    ``frame``: the config's ``frame:`` mapping (docs/six-axis.md), ATIDAQ's user tool
    transform: applied after the file's working matrix, as ``SetToolTransform`` does.

    Returns
    -------
    CouplingErrorModel
        ``method = "linear"``, ``matrix`` = ``projection`` = W (N x M, a zero column for
        the thermistor), k = 1, no chi, full scale from ``max``, ``temperature`` when
        the file compensates temperature; ``report.warnings`` says what the file
        holds beyond that (other calibrations, UserAxis rows that disagree).
    """
    from datetime import UTC, datetime

    from ..config import settings_from_dict
    from ..core.model import CouplingErrorModel, FitReport
    from ..core.temperature import TemperatureTerms

    cal = read_cal(path, index)
    name = cal.source
    comps = [a.name.lower() for a in cal.axes]
    bad = next((a for a in cal.axes if not a.max > 0), None)
    if bad is not None:
        raise InputError(f"{name}, element <Axis Name=\"{excerpt(bad.name)}\">: max is "
                         f"{bad.max:g}; the full scale comes from it, expected a positive number")
    for unit, known, key in ((cal.force_units, FORCE_UNITS, "ForceUnits"),
                             (cal.torque_units, TORQUE_UNITS, "TorqueUnits")):
        if unit not in known:
            raise InputError(f"{name}, element <Calibration>: {key} '{unit}' has no fsdecouple unit "
                             f"(known: {', '.join(known)})")
    outputs = [f"g{i}" for i in range(cal.num_gages)]
    if cal.temperature_compensated:
        outputs.append(THERMISTOR)
    clash = sorted(set(comps) & set(outputs))
    if clash:
        raise InputError(f"{name}, element <Axis Name=\"{excerpt(clash[0])}\">: the name of a gauge "
                         "output; expected axis names such as Fx .. Tz")
    loads = {c: FORCE_UNITS[cal.force_units] if a.name[:1] == "F" else TORQUE_UNITS[cal.torque_units]
             for c, a in zip(comps, cal.axes, strict=True)}
    serial = cal.sensor.get("Serial", "")
    raw = {
        "sensor": " ".join(x for x in ("ATI", cal.sensor.get("BodyStyle", ""), serial) if x) or "ATI",
        "components": comps, "outputs": outputs,
        "full_scale": {c: a.max for c, a in zip(comps, cal.axes, strict=True)},
        "units": {"load": loads, "output": "V"},
    }
    if frame is not None:
        from ..errors import ConfigError
        from ..wrench import parse_frame

        try:
            parse_frame(frame, f"{frame_source}: frame", len(comps))
        except ConfigError as err:
            raise InputError(str(err)) from None
        raw["frame"] = frame
    settings = settings_from_dict(raw, name)
    w = cal.working_matrix()
    m = np.zeros((len(comps), len(outputs)))
    m[:, :cal.num_gages] = w
    temperature = None
    if cal.temperature_compensated:
        zeros = (0.0,) * cal.num_gages
        b = -np.array([*(cal.bias_slope or zeros), 0.0])  # ATI's BS = -b, GS = -g
        g = -np.array([*(cal.gain_slope or zeros), 0.0])
        temperature = TemperatureTerms(len(outputs) - 1, cal.thermistor, b + 0.0, g + 0.0, "V")
    warnings = []
    if cal.count > 1:
        warnings.append(f"{name} holds {cal.count} calibrations; imported calibration {cal.index} "
                        "(choose another by its index)")
    agreement = user_axis_difference(cal, w)
    if agreement is not None and agreement > USER_AXIS_TOLERANCE:
        warnings.append(f"{name}: the UserAxis rows differ from the Axis rows and BasicTransform "
                        f"by up to {100 * agreement:.3g} % of max; decoupled from the Axis rows, as "
                        "ATIDAQ does")
    provenance: dict[str, Any] = {
        "imported_from": {"file": str(path), "sha256": cal.sha256,
                          "format": "ATI calibration (.cal)", "calibration_index": cal.index},
        "ati": {"sensor": cal.sensor, "calibration": cal.calibration,
                "basic_transform": dict(zip(TRANSFORM_KEYS, cal.basic_transform, strict=True)),
                "axis_names": [a.name for a in cal.axes],
                "user_axis_max_difference": agreement},
    }
    report = FitReport({}, {}, {}, {}, warnings=warnings)  # nothing was fitted
    return CouplingErrorModel(
        settings, np.ones(len(comps)), {}, report, provenance,
        datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"), "linear", m, {}, m.copy(),
        temperature=temperature)


# UserAxis rows are printed to about 5 digits: they agree with Axis / scale after
# the basic transform to ~1e-5 of max; beyond this they are not the same calibration
USER_AXIS_TOLERANCE = 1e-3


def user_axis_difference(cal: AtiCalibration, w: np.ndarray) -> float | None:
    """max over axes of |UserAxis - W| at full-scale gauge inputs, as a fraction of max.

    Each gauge's part is weighed by a unit gauge reading, so the figure is the largest
    force difference one volt on one gauge makes, relative to the axis's max.
    """
    if len(cal.user_axes) != len(cal.axes):
        return None
    user = {a.name: np.asarray(a.values) for a in cal.user_axes}
    diffs = [float(np.max(np.abs(user[a.name] - w[i]))) / a.max
             for i, a in enumerate(cal.axes) if a.name in user and a.max > 0]
    return max(diffs) if diffs else None


def check_log_gauges(model, header, source) -> None:
    """Refuse a log with gauge columns ``g<i>`` beyond an imported model's NumGages."""
    if not model.provenance.get("ati"):
        return
    outputs = {o.lower() for o in model.layout.outputs}
    extra = [h for h in header if re.fullmatch(r"[gG]\d+", str(h)) and str(h).lower() not in outputs]
    if extra:
        n = sum(o != THERMISTOR for o in model.layout.outputs)
        raise InputError(f"{printable(source)}, column '{excerpt(extra[0])}': the log has gauge "
                         f"columns beyond the calibration's NumGages = {n} (g0 .. g{n - 1}); is "
                         "this the calibration file of this sensor?")


def summary(model, output) -> dict[str, Any]:
    """``import``'s report: what was read, as lines and as the ``--json`` document."""
    ati = model.provenance.get("ati", {})
    units = model.settings.units
    comps = model.layout.labels
    gauges = [o for o in model.layout.outputs if o != THERMISTOR]
    fs = ", ".join(f"{c} {v:g} {units.load_of(a)}" for a, (c, v) in
                   enumerate(zip(comps, model.settings.full_scale, strict=True)))
    t = model.temperature
    lines = [f"wrote {printable(output)}: linear model of {model.settings.sensor}, "
             f"{len(comps)} components ({' '.join(comps)}) from {len(gauges)} gauges "
             f"({' '.join(gauges)})",
             f"full scale (max): {fs}",
             "temperature compensation: " + (f"yes (thermistor output, T0 = {t.t0:g} V)" if t
                                             else "no"),
             "bias: a zero (one value per output) or a tare of the first rows removes it"]
    return {"output": str(output), "sensor": model.settings.sensor, "components": list(comps),
            "outputs": list(model.layout.outputs),
            "full_scale": dict(zip(comps, map(float, model.settings.full_scale), strict=True)),
            "temperature_compensation": t is not None,
            "user_axis_max_difference": ati.get("user_axis_max_difference"),
            "warnings": model.warnings, "lines": lines}


def read_frame_config(path: str | Path) -> Any:
    """``import -c``: a YAML config holding ``frame:`` and nothing else."""
    from ..errors import ConfigError
    from ..yamlfile import read_yaml

    name = printable(path)
    raw = read_yaml(Path(path), name)
    if not isinstance(raw, dict) or "frame" not in raw:
        raise ConfigError(f"{name}: expected a mapping with frame: (the tool transform)")
    other = [k for k in raw if k != "frame"]
    if other:
        raise ConfigError(f"{name}: {excerpt(other[0])}: import reads only frame: from a config; "
                          "the sensor, units and full scale come from the .cal file")
    return raw["frame"]
