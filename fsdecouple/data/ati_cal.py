"""ATI calibration files (``.cal`` XML) in: the factory matrix as a linear model.

An ATI ``.cal`` file holds one ``FTSensor`` element (``NumGages`` strain gauges) with
one or more ``Calibration`` elements.  ATI's DAQ library (ATIDAQ, ftconfig.c and
ftrt.c) decouples from a calibration's ``Axis`` rows and ``BasicTransform``, never
from its ``UserAxis`` rows, and so does this module:

* the basic matrix: row i = ``Axis[i].values / Axis[i].scale`` (NumAxes x NumGages);
* for six axes, the working matrix W = T_basic B, with the tool transform of
  ``BasicTransform`` (Dx, Dy, Dz in DistUnits, Rx, Ry, Rz in AngleUnits):
  F' = R F, T' = R (T - d x F) (:func:`tool_transform`);
* forces F = W (G - G_bias), or with temperature compensation (``BiasSlope``,
  ``GainSlope``, ``Thermistor``) F = W (c(G, T) - c(G_bias, T_bias)), c the
  correction of :mod:`fsdecouple.core.temperature` with b = -BiasSlope,
  g = -GainSlope, T0 = Thermistor and T the thermistor channel.

The model is a ``linear`` model (:class:`~fsdecouple.core.model.CouplingErrorModel`)
with outputs ``g0 .. g{NumGages-1}`` (+ ``thermistor``), components named after
the ``Axis`` rows in lower case (``fx fy fz tx ty tz``), full scale from ``max``,
the file's force and torque units.  Parsed with defusedxml: a DTD (the carrier of
entity-expansion bombs) is refused before anything is expanded.
"""

from __future__ import annotations

import hashlib
import io
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError, excerpt, printable
from ..wrench import ati_rotation, wrench_transform

CAL_LIMIT = 1 << 20  # bytes: a .cal file is a few kB
MAX_GAUGES = 8  # ATIDAQ's MAX_GAUGES
THERMISTOR = "thermistor"
# ATI's unit names (ftconfig.c) -> fsdecouple's (units.py); klb has no fsdecouple unit
FORCE_UNITS = {"N": "N", "kN": "kN", "lb": "lbf", "lbf": "lbf", "kg": "kgf", "g": "gf"}
TORQUE_UNITS = {"N-m": "N·m", "Nm": "N·m", "N-mm": "N·mm", "Nmm": "N·mm",
                "lbf-in": "lbf·in", "lb-in": "lbf·in", "in-lb": "lbf·in", "in-lbf": "lbf·in",
                "lbf-ft": "lbf·ft", "lb-ft": "lbf·ft", "ft-lb": "lbf·ft", "ft-lbf": "lbf·ft",
                "kg-cm": "kgf·cm", "kgcm": "kgf·cm", "kN-m": "kN·m", "kNm": "kN·m"}
# ATIDAQ's conversion factors, per lbf, per lbf-in and per inch (ForceConv, TorqueConv,
# DistConv): a displacement d [DistUnits] times TorqueConv / (ForceConv DistConv) is a
# lever arm in torque unit per force unit
FORCE_PER_LBF = {"lb": 1.0, "lbf": 1.0, "klb": 1e-3, "klbf": 1e-3, "N": 4.44822161526,
                 "kN": 4.44822161526e-3, "kg": 0.45359237, "g": 453.59237}
TORQUE_PER_LBF_IN = {**dict.fromkeys(("in-lb", "in-lbf", "lb-in", "lbf-in"), 1.0),
                     **dict.fromkeys(("ft-lb", "lb-ft", "ft-lbf", "lbf-ft"), 1 / 12),
                     **dict.fromkeys(("N-m", "Nm"), 0.112984829028),
                     **dict.fromkeys(("N-mm", "Nmm"), 112.984829028),
                     **dict.fromkeys(("kg-cm", "kgcm"), 1.1521246198),
                     **dict.fromkeys(("kN-m", "kNm"), 0.000112984829028)}
DIST_PER_IN = {"in": 1.0, "m": 0.0254, "cm": 2.54, "mm": 25.4, "ft": 1 / 12}
ANGLE_DEGREES = {**dict.fromkeys(("deg", "degrees", "degree"), 1.0),
                 **dict.fromkeys(("rad", "radians", "radian"), 180.0 / math.pi)}
TRANSFORM_KEYS = ("Dx", "Dy", "Dz", "Rx", "Ry", "Rz")
_SEP = re.compile(r"[ \t]+")  # ATIDAQ's Separate(): values apart by spaces or tabs


@dataclass(frozen=True)
class AtiAxis:
    """One ``Axis`` (or ``UserAxis``) row: its name, NumGages values, ``max`` and ``scale``."""

    name: str
    values: tuple[float, ...]
    max: float
    scale: float = 1.0


@dataclass(frozen=True)
class AtiCalibration:
    """What a ``.cal`` file's ``FTSensor`` and chosen ``Calibration`` element say."""

    source: str
    num_gages: int
    axes: tuple[AtiAxis, ...]
    force_units: str
    torque_units: str
    dist_units: str
    angle_units: str = "degrees"
    basic_transform: tuple[float, ...] = (0.0,) * 6  # Dx Dy Dz [DistUnits], Rx Ry Rz [AngleUnits]
    user_axes: tuple[AtiAxis, ...] = ()
    bias_slope: tuple[float, ...] | None = None
    gain_slope: tuple[float, ...] | None = None
    thermistor: float = 0.0
    sensor: dict[str, str] = field(default_factory=dict)  # FTSensor's attributes, as written
    calibration: dict[str, str] = field(default_factory=dict)  # Calibration's attributes
    index: int = 1
    count: int = 1  # Calibration elements in the file

    @property
    def temperature_compensated(self) -> bool:
        """ATIDAQ's TempCompAvailable: a BiasSlope or a GainSlope row is present."""
        return self.bias_slope is not None or self.gain_slope is not None

    def basic_matrix(self) -> np.ndarray:
        """B, NumAxes x NumGages: each Axis row's values divided by its scale."""
        return np.array([np.asarray(a.values) / a.scale for a in self.axes])

    def working_matrix(self) -> np.ndarray:
        """W = T_basic B for six axes (ATIDAQ's default tool transform is the identity); B otherwise."""
        b = self.basic_matrix()
        if len(self.axes) != 6:
            return b  # ATIDAQ applies transforms to six-axis transducers only
        return tool_transform(self.basic_transform, self.force_units, self.torque_units,
                              self.dist_units, self.angle_units) @ b


def tool_transform(tt, force_units: str, torque_units: str, dist_units: str,
                   angle_units: str = "degrees") -> np.ndarray:
    """ATIDAQ's 6 x 6 tool transform of (Dx, Dy, Dz, Rx, Ry, Rz): F' = R F, T' = R (T - d x F).

    d [DistUnits] is converted to torque unit per force unit; R is built from the
    angles as ATIDAQ builds it (:func:`fsdecouple.wrench.ati_rotation`), the config's
    ``frame: {angles, displacement}`` being the same transform after the decoupling.
    """
    lever = TORQUE_PER_LBF_IN[torque_units] / (FORCE_PER_LBF[force_units] * DIST_PER_IN[dist_units])
    d = np.asarray(tt[:3], dtype=float) * lever
    return wrench_transform(ati_rotation([float(a) * ANGLE_DEGREES[angle_units] for a in tt[3:]]), d)


# --- reading -------------------------------------------------------------------------

def _parse(data: bytes, name: str):
    """The element tree, or one line naming the element where the XML breaks."""
    import defusedxml
    import defusedxml.ElementTree as DET

    stack: list[str] = []
    root = None
    try:
        for event, elem in DET.iterparse(io.BytesIO(data), events=("start", "end"), forbid_dtd=True):
            if event == "start":
                stack.append(elem.tag)
                root = elem if root is None else root
            else:
                stack.pop()
    except (defusedxml.DTDForbidden, defusedxml.EntitiesForbidden,
            defusedxml.ExternalReferenceForbidden) as err:
        what = getattr(err, "name", None) or "?"
        raise InputError(f"{name}: element <!DOCTYPE {excerpt(what)}>: a DTD or entity declaration "
                         "(the carrier of entity-expansion bombs) is refused; an ATI calibration "
                         "file has none") from None
    except SyntaxError as err:  # xml.etree.ElementTree.ParseError
        line, col = getattr(err, "position", (None, None))
        inside = f"inside element <{excerpt(stack[-1])}>" if stack else "before any element"
        cut = "truncated" if stack and line is not None and _at_end(data, line, col) else "malformed"
        raise InputError(f"{name}: not well-formed XML ({cut} {inside}, line {line}, column "
                         f"{(col or 0) + 1}: {excerpt(str(err).split(':')[0])}); expected an ATI "
                         "calibration file") from None
    if root is None:
        raise InputError(f"{name}: no XML element; expected an ATI calibration file")
    return root


def _at_end(data: bytes, line: int, col: int) -> bool:
    lines = data.rstrip().split(b"\n")
    return line >= len(lines)


def _attr(elem, key: str, name: str, where: str, *, required: bool = True, default=None):
    value = elem.get(key)
    if value is None or value.strip() == "":
        if required:
            raise InputError(f"{name}, element {where}: attribute {key} is missing")
        return default
    return value


def _number(text: str, name: str, where: str, key: str) -> float:
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not math.isfinite(v):
        raise InputError(f"{name}, element {where}: {key} '{excerpt(text)}' is not a finite number")
    return v


def _values(text: str, n: int, name: str, where: str, key: str = "values") -> tuple[float, ...]:
    words = [w for w in _SEP.split(text.strip()) if w]
    if len(words) != n:
        raise InputError(f"{name}, element {where}: {key} holds {len(words)} numbers, expected "
                         f"{n} (NumGages)")
    return tuple(_number(w, name, where, key) for w in words)


def _axis(elem, n: int, name: str, tag: str, i: int, user: bool) -> AtiAxis:
    axis_name = elem.get("Name")
    where = f"<{tag} Name=\"{excerpt(axis_name)}\">" if axis_name else f"<{tag}> (row {i + 1})"
    if not axis_name:
        raise InputError(f"{name}, element {where}: attribute Name is missing")
    values = _values(_attr(elem, "values", name, where), n, name, where)
    mx = _number(_attr(elem, "max", name, where, required=False, default="0"), name, where, "max")
    scale = 1.0 if user else _number(_attr(elem, "scale", name, where, required=False, default="1"),
                                     name, where, "scale")
    if scale == 0.0:
        raise InputError(f"{name}, element {where}: scale is 0; each value is divided by it")
    return AtiAxis(axis_name, values, mx, scale)


def read_cal(path: str | Path, index: int = 1) -> AtiCalibration:
    """Read calibration ``index`` (1-based, as ATIDAQ counts) of the ATI file ``path``."""
    from ..files import read_bounded

    path = Path(path)
    name = printable(path)
    try:
        data = read_bounded(path, CAL_LIMIT, "an ATI calibration file")
    except FileNotFoundError:
        raise InputError(f"{name}: calibration file not found") from None
    except OSError as err:
        raise InputError(f"{name}: cannot read ({err.strerror or err})") from None
    root = _parse(data, name)
    if root.tag != "FTSensor":
        raise InputError(f"{name}: root element <{excerpt(root.tag)}>, expected <FTSensor> "
                         "(not an ATI calibration file)")
    gages = _attr(root, "NumGages", name, "<FTSensor>")
    if not gages.strip().isdigit() or not 1 <= int(gages) <= MAX_GAUGES:
        raise InputError(f"{name}, element <FTSensor>: NumGages '{excerpt(gages)}', expected a whole "
                         f"number from 1 to {MAX_GAUGES}")
    n = int(gages)
    cals = root.findall(".//Calibration")
    if not cals:
        raise InputError(f"{name}, element <FTSensor>: no <Calibration> element")
    if not 1 <= index <= len(cals):
        raise InputError(f"{name}: calibration {index} asked for, the file holds {len(cals)}")
    cal = cals[index - 1]
    where = "<Calibration>"
    units = {k: _attr(cal, k, name, where) for k in ("ForceUnits", "TorqueUnits", "DistUnits")}
    angle = _attr(cal, "AngleUnits", name, where, required=False, default="degrees")
    for key, known in (("ForceUnits", FORCE_PER_LBF), ("TorqueUnits", TORQUE_PER_LBF_IN),
                       ("DistUnits", DIST_PER_IN)):
        if units[key] not in known:
            raise InputError(f"{name}, element {where}: {key} '{excerpt(units[key])}' is not a unit "
                             f"ATIDAQ knows ({', '.join(known)})")
    if angle not in ANGLE_DEGREES:
        raise InputError(f"{name}, element {where}: AngleUnits '{excerpt(angle)}' is not a unit "
                         f"ATIDAQ knows ({', '.join(ANGLE_DEGREES)})")
    axes = tuple(_axis(e, n, name, "Axis", i, False) for i, e in enumerate(cal.findall(".//Axis")))
    if not axes:
        raise InputError(f"{name}, element {where}: no <Axis> rows")
    users = tuple(_axis(e, n, name, "UserAxis", i, True)
                  for i, e in enumerate(cal.findall(".//UserAxis")))
    names = [a.name.lower() for a in axes]
    twice = next((a for a in names if names.count(a) > 1), None)
    if twice:
        raise InputError(f"{name}, element <Axis Name=\"{excerpt(twice)}\">: named twice")
    tt, bias, gain, therm = (0.0,) * 6, None, None, 0.0
    for child in cal:  # ATIDAQ reads these among the Calibration's own children
        if child.tag == "BasicTransform":
            tt = tuple(_number(_attr(child, k, name, "<BasicTransform>", required=False,
                                     default="0"), name, "<BasicTransform>", k)
                       for k in TRANSFORM_KEYS)
        elif child.tag == "BiasSlope":
            bias = _values(_attr(child, "values", name, "<BiasSlope>"), n, name, "<BiasSlope>")
        elif child.tag == "GainSlope":
            gain = _values(_attr(child, "values", name, "<GainSlope>"), n, name, "<GainSlope>")
        elif child.tag == "Thermistor":
            therm = _number(_attr(child, "value", name, "<Thermistor>"), name, "<Thermistor>",
                            "value")
    return AtiCalibration(
        source=name, num_gages=n, axes=axes, force_units=units["ForceUnits"],
        torque_units=units["TorqueUnits"], dist_units=units["DistUnits"], angle_units=angle,
        basic_transform=tt, user_axes=users, bias_slope=bias, gain_slope=gain, thermistor=therm,
        sensor=dict(root.attrib), calibration=dict(cal.attrib), index=index, count=len(cals))


# --- the model -------------------------------------------------------------------------

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
        from ..config import ConfigError
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
                        "(import --index N for another)")
    agreement = user_axis_difference(cal, w)
    if agreement is not None and agreement > USER_AXIS_TOLERANCE:
        warnings.append(f"{name}: the UserAxis rows differ from the Axis rows and BasicTransform "
                        f"by up to {100 * agreement:.3g} % of max; decoupled from the Axis rows, as "
                        "ATIDAQ does")
    data = Path(path).read_bytes()
    provenance: dict[str, Any] = {
        "imported_from": {"file": str(path), "sha256": hashlib.sha256(data).hexdigest(),
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
             "bias: apply --zero (one value per output) or --tare N removes it"]
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
