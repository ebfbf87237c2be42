"""ATI calibration files (``.cal`` XML) in: what the file says, read as ATIDAQ reads it.

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

:mod:`fsdecouple.data.ati_model` makes the model of it.  Parsed with defusedxml: a
DTD (the carrier of entity-expansion bombs) is refused before anything is expanded.
"""

from __future__ import annotations

import hashlib
import io
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError, excerpt, printable
from ..wrench import ati_rotation, wrench_transform

CAL_LIMIT = 1 << 20  # bytes: a .cal file is a few kB
MAX_GAUGES = 8  # ATIDAQ's MAX_GAUGES
THERMISTOR = "thermistor"
# ATI's unit names (ftconfig.c) -> fsdecouple's (units.py)
FORCE_UNITS = {"N": "N", "kN": "kN", "lb": "lbf", "lbf": "lbf", "klb": "klbf", "klbf": "klbf",
               "kg": "kgf", "g": "gf"}
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
    sha256: str = ""  # of the bytes read

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
        # expat's words for a document that stops early (not a wrong tag or character)
        cut = "truncated" if str(err).startswith(("no element found", "unclosed token",
                                                  "unclosed CDATA")) else "malformed"
        raise InputError(f"{name}: not well-formed XML ({cut} {inside}, line {line}, column "
                         f"{(col or 0) + 1}: {excerpt(str(err).split(':')[0])}); expected an ATI "
                         "calibration file") from None
    if root is None:
        raise InputError(f"{name}: no XML element; expected an ATI calibration file")
    return root


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
    from ..files.inputs import read_bounded

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
    twice = next((a.name for a in axes if names.count(a.name.lower()) > 1), None)
    if twice:
        raise InputError(f"{name}, element <Axis Name=\"{excerpt(twice)}\">: two Axis rows have "
                         "this name (case aside)")
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
        sensor=dict(root.attrib), calibration=dict(cal.attrib), index=index, count=len(cals),
        sha256=hashlib.sha256(data).hexdigest())
