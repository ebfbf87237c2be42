"""Settings: the sensor, the file layout and the epsilon-SVR parameters.

A YAML file (``configs/paper-sensor.yaml`` describes the paper's sensor) is read
with ``yaml.safe_load`` into a frozen :class:`Settings`; command-line flags
override it.  The built-in defaults *are* the paper's sensor (Section 3) and
Table 2, so running without a config reproduces the paper's set-up.
"""

from __future__ import annotations

import difflib
import math
import numbers
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from .axes import CANONICAL_COLUMNS, CHI_SEPARATOR, DEFAULT, FORCE_COLUMNS, VOLTAGE_COLUMNS, Layout
from .errors import ConfigError, printable
from .labinfo import LAB_KEYS, LabInfo, lab_from_dict
from .units import LOAD_UNITS, MOMENT_UNITS, OUTPUT_UNITS, Units, temperature_keys
from .wrench import Frame, parse_frame, parse_rotation
from .yamlfile import SafeUniqueLoader, read_yaml  # noqa: F401 (the loader, for tests)

SCALINGS = ("none", "full_scale")
NOT_CSV = "0123456789eE+-\"\r\n"  # csv: characters that stand inside a number or a quoted cell
CSV_CHARS = {"decimal": "'.' or ','", "sep": "one character that is no digit, sign, 'e', quote or line break"}
ZERO_MODES = ("rows", "fit")  # how sweeps are zeroed: Section 3, or zero.fitted_offsets
# chi beyond its range (core/extrapolation.py): tangent for new fits, kernel for older files
EXTRAPOLATIONS = DEFAULT_EXTRAPOLATION, LEGACY_EXTRAPOLATION = ("tangent", "kernel")
MAX_REFINE = 100  # refinement steps (core/decouple.py): each gains about a digit


@dataclass(frozen=True)
class SVRSettings:
    """epsilon-SVR parameters of Table 2 (libsvm ``-s 3 -t 2``).

    ``gamma`` is libsvm's kernel parameter, ``exp(-gamma |u - v|^2)``; the paper's
    Gaussian ``exp(-|u - v|^2 / 2 delta^2)`` with delta^2 = 1 gives gamma = 0.5.
    """

    C: float = 1000.0
    epsilon: float = 0.0001
    gamma: float = 0.5
    tolerance: float = 0.001

    @property
    def delta2(self) -> float:
        return 1.0 / (2.0 * self.gamma)

    def libsvm_options(self) -> str:
        return (f"-s 3 -t 2 -g {self.gamma!r} -c {self.C!r} -p {self.epsilon!r} "
                f"-e {self.tolerance!r} -q")


@dataclass(frozen=True)
class Settings:
    """Everything given (not learned) for fitting and applying a model."""

    sensor: str = "paper-3axis"
    full_scale: tuple[float, ...] = (100.0, 100.0, 150.0)  # [N], Section 3; per component
    min_repetitions: int = 6
    columns: dict[str, str] = field(default_factory=lambda: {c: c for c in CANONICAL_COLUMNS})
    scale: dict[str, float] = field(
        default_factory=lambda: {c: 1.0 for c in (*FORCE_COLUMNS, *VOLTAGE_COLUMNS)}
    )
    sep: str = ","
    decimal: str = "."
    # raw output range of each channel (ADC or amplifier), before zero correction
    limits: dict[str, tuple[float, float]] = field(default_factory=dict)
    svr: SVRSettings = SVRSettings()
    scaling: str = "none"
    rotation: tuple[tuple[float, float, float], ...] | None = None
    min_r2: float = 0.99
    refine: int = 0  # fixed-point steps on the prime outputs before eq. (11) (decouple.py)
    extrapolation: str = DEFAULT_EXTRAPOLATION  # model files without it: kernel
    units: Units = Units()
    # the sensor's components and their prime outputs (axes.Layout); None: x, y, z
    components: tuple[str, ...] | None = None
    outputs: tuple[str, ...] | None = None
    zero: str | None = None  # ZERO_MODES; None: rows for x, y, z, fit for components
    frame: Frame | None = None  # six axes: the wrench transform after eq. (11) (wrench.py)
    lab: LabInfo = LabInfo()  # the certificate's serial, reference, environment (labinfo.py)

    @property
    def zero_method(self) -> str:
        return self.zero or ("rows" if self.components is None else "fit")

    @property
    def layout(self) -> Layout:
        if self.components is None:
            return DEFAULT
        return Layout.named(self.components, self.outputs)

    @property
    def load_unit(self) -> str:
        return self.units.load

    @property
    def output_unit(self) -> str:
        return self.units.output

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        if not self.limits:
            del d["limits"]  # files from before limits keep their bytes
        layout = self.layout
        d["full_scale"] = dict(zip(layout.labels, self.full_scale, strict=True))
        if self.zero is None:
            del d["zero"]
        if self.frame is None:
            del d["frame"]
        else:
            d["frame"] = self.frame.to_dict()
        if self.components is None:
            del d["components"], d["outputs"]  # files from before components keep their bytes
        else:
            d["components"], d["outputs"] = list(self.components), list(self.outputs)
        d["rotation"] = None if self.rotation is None else [list(r) for r in self.rotation]
        d["csv"] = {"sep": d.pop("sep"), "decimal": d.pop("decimal")}
        d.pop("lab")
        d.update(self.lab.to_dict())  # none of its keys when all are defaults
        d["checks"] = {"min_r2": d.pop("min_r2")}
        if self.refine == 0:
            del d["refine"]  # eq. (11) as written: files from before refine keep their bytes
        if self.units == Units():
            del d["units"]  # the paper's N and V: files from before units keep their bytes
        else:
            d["units"] = self.units.to_dict(layout.loads, layout.outputs)
        return d


_TOP_KEYS = {
    "limits", "refine", "extrapolation", "sensor", "full_scale", "min_repetitions", "columns",
    "scale", "csv", "svr", "scaling", "rotation", "checks", "units", "components", "outputs",
    "zero", "frame", *LAB_KEYS,
}
_SVR_KEYS = {"C", "epsilon", "gamma", "delta2", "tolerance"}


def _unknown(key: str, allowed: set[str], where: str) -> ConfigError:
    hint = difflib.get_close_matches(key, sorted(allowed), n=1)
    did_you_mean = f" (did you mean '{hint[0]}'?)" if hint else ""
    return ConfigError(f"{where}: unknown key '{key}'{did_you_mean}; allowed: {', '.join(sorted(allowed))}")


def _number(value: Any, where: str, *, positive: bool = False, within: tuple | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{where}: expected a number, found {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise ConfigError(f"{where}: expected a finite number, found {value!r}")
    if positive and v <= 0:
        raise ConfigError(f"{where}: must be greater than 0, found {value!r}")
    if within and not within[0] <= v <= within[1]:
        raise ConfigError(f"{where}: expected {within[0]:g} .. {within[1]:g}, found {value!r}")
    return v


def check_refine(value: Any, where: str = "refine") -> int:
    """The number K of refinement steps: a whole number from 0 to MAX_REFINE."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) \
            or not 0 <= value <= MAX_REFINE:
        raise ConfigError(f"{where}: expected a whole number of refinement steps from 0 to "
                          f"{MAX_REFINE}, found {value!r}")
    return int(value)


def check_zero(value: Any, where: str = "zero") -> str:
    """How sweeps are zeroed: ``rows`` (Section 3) or ``fit`` (all points, zero.fitted_offsets)."""
    return check_choice(value, where, ZERO_MODES)


def check_choice(value: Any, where: str = "extrapolation", modes=EXTRAPOLATIONS) -> str:
    """One of ``modes``: by default the extrapolation mode (core/extrapolation.py)."""
    if not isinstance(value, str) or value not in modes:
        raise ConfigError(f"{where}: expected one of {', '.join(modes)}, found {value!r}")
    return value


check_extrapolation = check_choice


def _mapping(value: Any, where: str) -> dict:
    if not isinstance(value, dict):
        raise ConfigError(f"{where}: expected a mapping, found {type(value).__name__} {value!r}")
    return value


def _svr_settings(raw: Any, where: str, base: SVRSettings) -> SVRSettings:
    raw = _mapping(raw, where)
    for key in raw:
        if key not in _SVR_KEYS:
            raise _unknown(key, _SVR_KEYS, where)
    if "gamma" in raw and "delta2" in raw:
        raise ConfigError(f"{where}: give either 'gamma' or 'delta2' (gamma = 1/(2 delta2)), not both")
    # within 1e-12 .. 1e12 (docs/errors.md): a gamma of 1e308 overflowed the kernel's sums
    kw = {k: _number(raw[k], f"{where}: {k}", within=(1e-12, 1e12)) for k in _SVR_KEYS if k in raw}
    if "delta2" in kw:
        kw["gamma"] = 1.0 / (2.0 * kw.pop("delta2"))
    return replace(base, **kw)


def _units(raw: Any, where: str, layout: Layout = DEFAULT) -> Units:
    """``{load: N, output: V}``, or per column: ``{load: {fx: N, mx: N·m}, output: {u1: V}}``."""
    raw = _mapping(raw, where)
    loads = (*LOAD_UNITS, *(() if layout.is_default else MOMENT_UNITS))
    allowed = {"load": loads, "output": (*OUTPUT_UNITS, *loads)}  # a factory-calibrated N, N·m
    columns = {"load": layout.loads, "output": layout.outputs}
    for key in raw:
        if key not in allowed:
            raise _unknown(str(key), set(allowed), where)
    kw: dict[str, Any] = {}
    for key, units in allowed.items():
        if key not in raw:
            continue
        value = raw[key]
        if isinstance(value, dict):
            for col in value:
                if col not in columns[key]:
                    raise _unknown(str(col), set(columns[key]), f"{where}: {key}")
            missing = [c for c in columns[key] if c not in value]
            if missing:
                raise ConfigError(f"{where}: {key}: no unit for {', '.join(missing)}; give one "
                                  "per column, or one unit for all")
            per = tuple(value[c] for c in columns[key])
        else:
            per = (value,)
        for unit in per:
            if unit not in units:
                raise ConfigError(f"{where}: {key}: unknown unit {unit!r}; expected one of "
                                  f"{', '.join(units)}")
        if len(set(per)) == 1:
            kw[key] = per[0]
        else:  # mixed units: shown column by column, never converted as one
            kw[key] = " / ".join(dict.fromkeys(per))
            kw[f"{key}s"] = per
    return Units(**kw)


def _names(raw: Any, where: str) -> tuple[str, ...]:
    """A list of distinct column names (``components:`` or ``outputs:``)."""
    if not (isinstance(raw, list) and raw):
        raise ConfigError(f"{where}: expected a list of names, found {raw!r}")
    for name in raw:
        if not isinstance(name, str) or not name.strip() or CHI_SEPARATOR in name \
                or name != name.strip():
            raise ConfigError(f"{where}: {name!r} is not a name (text without '{CHI_SEPARATOR}' "
                              "or surrounding spaces)")
    seen: dict[str, int] = {}
    for i, name in enumerate(raw):
        if name.lower() in seen:
            raise ConfigError(f"{where}: '{name}' is listed twice (places {seen[name.lower()] + 1} "
                              f"and {i + 1}); each needs its own")
        seen[name.lower()] = i
    return tuple(raw)


def _layout(raw: dict, source: str) -> tuple[tuple[str, ...], tuple[str, ...]] | None:
    """``components`` and ``outputs``: N loads and each one's prime output, or M > N outputs."""
    if "components" not in raw and "outputs" not in raw:
        return None
    if "components" not in raw or "outputs" not in raw:
        given, other = ("components", "outputs") if "components" in raw else ("outputs", "components")
        raise ConfigError(f"{source}: {given} needs {other}: the prime output of each component, "
                          "in the same order")
    comps = _names(raw["components"], f"{source}: components")
    outs = _names(raw["outputs"], f"{source}: outputs")
    if len(outs) < len(comps):
        raise ConfigError(f"{source}: outputs: {len(outs)} names for {len(comps)} components; "
                          "each component has one prime output, in the same order, or more")
    if len(comps) < 2:
        raise ConfigError(f"{source}: components: a coupling model needs at least 2 components")
    clash = sorted({c.lower() for c in comps} & {o.lower() for o in outs})
    if clash or {"repetition", "axis"} & {n.lower() for n in (*comps, *outs)}:
        name = clash[0] if clash else "repetition/axis"
        raise ConfigError(f"{source}: outputs: '{name}' names a component and an output at once "
                          "(or a reserved column)")
    if "full_scale" not in raw:
        raise ConfigError(f"{source}: full_scale: a sensor with components needs the full scale "
                          "of each")
    return comps, outs


def _limits(raw: Any, where: str, outputs=VOLTAGE_COLUMNS) -> dict[str, tuple[float, float]]:
    """``{ux: [lo, hi], ...}``: the raw range of each output, in the data's units."""
    raw = _mapping(raw, where)
    out = {}
    for key, pair in raw.items():
        if key not in outputs:
            raise _unknown(str(key), set(outputs), where)
        if not (isinstance(pair, list | tuple) and len(pair) == 2):
            raise ConfigError(f"{where}: {key}: expected [lo, hi], found {pair!r}")
        lo, hi = (_number(v, f"{where}: {key}") for v in pair)
        if not lo < hi:
            raise ConfigError(f"{where}: {key}: expected lo < hi, found [{pair[0]!r}, {pair[1]!r}]")
        out[key] = (lo, hi)
    return out


FULL_SCALE_RANGE = (1e-12, 1e12)


@temperature_keys  # columns: {temperature: ...}, units: {temperature: ...} (temperature_units.py)
def settings_from_dict(raw: Any, source: str = "config") -> Settings:
    """Validate a parsed YAML document into :class:`Settings` (unknown keys refused)."""
    raw = _mapping({} if raw is None else raw, source)
    for key in raw:
        if key not in _TOP_KEYS:
            raise _unknown(str(key), _TOP_KEYS, source)
    s = Settings()
    kw: dict[str, Any] = {}
    named = _layout(raw, source)
    if named is not None:
        layout = Layout.named(*named)
        s = replace(s, components=named[0], outputs=named[1],
                    columns={c: c for c in layout.canonical},
                    scale={c: 1.0 for c in (*layout.loads, *layout.outputs)},
                    full_scale=(1.0,) * layout.n)
    layout = s.layout
    if "sensor" in raw:
        if not isinstance(raw["sensor"], str) or not raw["sensor"].strip():
            raise ConfigError(f"{source}: sensor: expected a name, found {raw['sensor']!r}")
        kw["sensor"] = raw["sensor"]
    if "full_scale" in raw:
        fs = _mapping(raw["full_scale"], f"{source}: full_scale")
        for key in fs:
            if key not in layout.labels:
                raise _unknown(str(key), set(layout.labels), f"{source}: full_scale")
        missing = [a for a in layout.labels if a not in fs]
        if missing:
            raise ConfigError(f"{source}: full_scale: missing axis {', '.join(missing)}")
        kw["full_scale"] = tuple(
            _number(fs[a], f"{source}: full_scale: {a}", positive=True) for a in layout.labels
        )
    if "min_repetitions" in raw:
        v = raw["min_repetitions"]
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise ConfigError(f"{source}: min_repetitions: expected a whole number >= 1, found {v!r}")
        kw["min_repetitions"] = v
    if "columns" in raw:
        cols = _mapping(raw["columns"], f"{source}: columns")
        merged = dict(s.columns)
        for key, name in cols.items():
            if key not in layout.canonical:
                raise _unknown(str(key), set(layout.canonical), f"{source}: columns")
            if not isinstance(name, str) or not name:
                raise ConfigError(f"{source}: columns: {key}: expected a column name, found {name!r}")
            merged[key] = name
        if len(set(merged.values())) != len(merged):
            twice = next(v for v in merged.values() if list(merged.values()).count(v) > 1)
            keys = [k for k, v in merged.items() if v == twice]
            raise ConfigError(f"{source}: columns: two quantities map to the same file column "
                              f"('{twice}': {' and '.join(keys)})")
        kw["columns"] = merged
    if "scale" in raw:
        sc = _mapping(raw["scale"], f"{source}: scale")
        merged_scale = dict(s.scale)
        for key, value in sc.items():
            if key not in merged_scale:
                raise _unknown(str(key), set(merged_scale), f"{source}: scale")
            v = _number(value, f"{source}: scale: {key}")
            if v == 0:
                raise ConfigError(f"{source}: scale: {key}: must not be 0")
            merged_scale[key] = v
        kw["scale"] = merged_scale
    if "csv" in raw:
        csv = _mapping(raw["csv"], f"{source}: csv")
        for key, value in csv.items():
            if key not in ("sep", "decimal"):
                raise _unknown(str(key), {"sep", "decimal"}, f"{source}: csv")
            if not isinstance(value, str) or len(value) != 1 or value in NOT_CSV \
                    or (key == "decimal" and value not in ".,"):
                raise ConfigError(f"{source}: csv: {key}: expected {CSV_CHARS[key]}, found {value!r}")
            kw[key] = value
        if kw.get("sep", ",") == kw.get("decimal", "."):
            raise ConfigError(f"{source}: csv: sep and decimal must differ")
    if "svr" in raw:
        kw["svr"] = _svr_settings(raw["svr"], f"{source}: svr", s.svr)
    if "scaling" in raw:
        if raw["scaling"] not in SCALINGS:
            raise ConfigError(
                f"{source}: scaling: expected one of {', '.join(SCALINGS)}, found {raw['scaling']!r}"
            )
        kw["scaling"] = raw["scaling"]
    if "rotation" in raw:
        kw["rotation"] = parse_rotation(raw["rotation"], f"{source}: rotation")
        if kw["rotation"] is not None and layout.n != 3:
            raise ConfigError(f"{source}: rotation: rotates three forces; a sensor of "
                              f"{layout.n} components takes frame: {{rotation, origin}}")
    if raw.get("frame") is not None:
        kw["frame"] = parse_frame(raw["frame"], f"{source}: frame", layout.n)
    if "limits" in raw:
        kw["limits"] = _limits(raw["limits"], f"{source}: limits", layout.outputs)
    if "refine" in raw:
        kw["refine"] = check_refine(raw["refine"], f"{source}: refine")
    if "zero" in raw:
        kw["zero"] = check_zero(raw["zero"], f"{source}: zero")
    if "extrapolation" in raw:
        kw["extrapolation"] = check_extrapolation(raw["extrapolation"], f"{source}: extrapolation")
    if "units" in raw:
        kw["units"] = _units(raw["units"], f"{source}: units", layout)
        if "scaling" not in raw and kw["units"].output != "V":
            # Table 2's kernel width assumes outputs of order 1 V
            kw["scaling"] = "full_scale"
    kw.update(lab_from_dict(raw, source))
    if "checks" in raw:
        checks = _mapping(raw["checks"], f"{source}: checks")
        for key, value in checks.items():
            if key != "min_r2":
                raise _unknown(str(key), {"min_r2"}, f"{source}: checks")
            kw["min_r2"] = _number(value, f"{source}: checks: min_r2", positive=True)
    return replace(s, **kw)


def load_config(path: str | Path | None = None, **overrides: Any) -> Settings:
    """Read a YAML config (``None``: the built-in paper sensor) and apply overrides.

    Overrides are flag values; ``None`` means "not given".  SVR keys (``C``,
    ``epsilon``, ``gamma``, ``delta2``, ``tolerance``) go to :class:`SVRSettings`.
    """
    if path is None:
        settings = Settings()
    else:
        path = Path(path)
        name = printable(path)
        raw = read_yaml(path, name)
        settings = settings_from_dict(raw, name)
    settings = apply_overrides(settings, **overrides)
    for axis, value in zip(settings.layout.labels, settings.full_scale, strict=True):
        low, high = FULL_SCALE_RANGE
        if not low <= value <= high:
            raise ConfigError(f"{name if path is not None else 'config'}: full_scale: {axis}: "
                              f"{value!r} is outside {low:g} .. {high:g}")
    return settings


def apply_overrides(settings: Settings, **overrides: Any) -> Settings:
    given = {k: v for k, v in overrides.items() if v is not None}
    svr_raw = {k: given.pop(k) for k in list(given) if k in _SVR_KEYS}
    if svr_raw:
        settings = replace(settings, svr=_svr_settings(svr_raw, "command-line SVR setting", settings.svr))
    if "scaling" in given and given["scaling"] not in SCALINGS:
        raise ConfigError(f"--scaling: expected one of {', '.join(SCALINGS)}, found {given['scaling']!r}")
    if "refine" in given:
        given["refine"] = check_refine(given["refine"], "--refine")
    if "extrapolation" in given:
        given["extrapolation"] = check_extrapolation(given["extrapolation"], "--extrapolation")
    return replace(settings, **given)
