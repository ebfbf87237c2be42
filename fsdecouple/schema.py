"""The config's keys, declared once: name, type and bounds, default, doc, who reads it.

:data:`SCHEMA` lists every top-level key of a YAML config as a :class:`Key`: the
validator that turns its value into :class:`~fsdecouple.config.Settings` fields
(a type with bounds, such as :class:`Whole` or :class:`Choice`, or a function for the
keys that hold a structure), its default as a reader sees it, one line of doc, and
whether ``apply`` reads it from a config (``applies``: how a log is read) or takes it
from the model (everything fitted).  :func:`validate` walks the table: an unknown key
is refused with a "did you mean" hint, and so is every malformed value, naming the
file and the key.
"""

from __future__ import annotations

import difflib
import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

from .axes import CHI_SEPARATOR, VOLTAGE_COLUMNS, Layout
from .errors import ConfigError
from .labinfo import LAB_KEYS, lab_from_dict
from .units import LOAD_UNITS, MOMENT_UNITS, OUTPUT_UNITS, Units
from .wrench import parse_frame, parse_rotation

# Settings and SVRSettings (config.py, which imports this module) are duck-typed here:
# a reader gets the settings so far and returns the fields its key sets
Settings = SVRSettings = Any

SCALINGS = ("none", "full_scale")
NOT_CSV = "0123456789eE+-\"\r\n"  # csv: characters that stand inside a number or a quoted cell
CSV_CHARS = {"decimal": "'.' or ','", "sep": "one character that is no digit, sign, 'e', quote or line break"}
FIT_METHODS = ("svr", "linear", "auto")  # fit --method, the config's method (evaluation/calibrate.py)
ZERO_MODES = ("rows", "fit", "intercept")  # Section 3; zero.fitted_offsets; zero.intercept_offsets
# chi beyond its range (core/extrapolation.py): tangent for new fits, kernel for older files
EXTRAPOLATIONS = DEFAULT_EXTRAPOLATION, LEGACY_EXTRAPOLATION = ("tangent", "kernel")
MAX_REFINE = 100  # refinement steps (core/decouple.py): each gains about a digit
SVR_RANGE = (1e-12, 1e12)  # docs/errors.md: a gamma of 1e308 overflowed the kernel's sums
SVR_KEYS = ("C", "epsilon", "gamma", "delta2", "tolerance")


# --- value types ------------------------------------------------------------------


def unknown(key: str, allowed, where: str) -> ConfigError:
    """An unknown key, with the closest allowed one as a hint."""
    hint = difflib.get_close_matches(key, sorted(allowed), n=1)
    did_you_mean = f" (did you mean '{hint[0]}'?)" if hint else ""
    return ConfigError(f"{where}: unknown key '{key}'{did_you_mean}; allowed: {', '.join(sorted(allowed))}")


def mapping(value: Any, where: str) -> dict:
    if not isinstance(value, dict):
        raise ConfigError(f"{where}: expected a mapping, found {type(value).__name__} {value!r}")
    return value


def number(value: Any, where: str, *, positive: bool = False, within: tuple | None = None) -> float:
    """A finite number (YAML int or float, never a bool), optionally > 0 or within bounds."""
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


@dataclass(frozen=True)
class Whole:
    """A whole number from ``low`` to ``high`` (YAML int; never a bool)."""

    low: int
    high: int | None = None
    what: str = "a whole number"

    def __call__(self, value: Any, where: str) -> int:
        if isinstance(value, bool) or not isinstance(value, numbers.Integral) \
                or value < self.low or (self.high is not None and value > self.high):
            bound = f"from {self.low} to {self.high}" if self.high is not None else f">= {self.low}"
            raise ConfigError(f"{where}: expected {self.what} {bound}, found {value!r}")
        return int(value)


@dataclass(frozen=True)
class Choice:
    """One of ``options``."""

    options: tuple[str, ...]

    def __call__(self, value: Any, where: str) -> str:
        if not isinstance(value, str) or value not in self.options:
            raise ConfigError(f"{where}: expected one of {', '.join(self.options)}, found {value!r}")
        return value


def check_refine(value: Any, where: str = "refine") -> int:
    """The number K of refinement steps: a whole number from 0 to MAX_REFINE."""
    return Whole(0, MAX_REFINE, "a whole number of refinement steps")(value, where)


def refine_argument(value: Any, where: str = "refine") -> int:
    """:func:`check_refine` of a ``refine`` argument (``apply --refine``, ``cv --refine``),
    its error naming the argument for the command line to spell as a flag."""
    try:
        return check_refine(value, where)
    except ConfigError as err:
        raise ConfigError(str(err), argument="refine") from None


def check_choice(value: Any, where: str = "extrapolation", modes=EXTRAPOLATIONS) -> str:
    """One of ``modes``: by default the extrapolation mode (core/extrapolation.py)."""
    return Choice(tuple(modes))(value, where)


check_extrapolation = check_choice


def check_zero(value: Any, where: str = "zero") -> str:
    """How sweeps are zeroed: ``rows`` (Section 3) or ``fit`` (all points, zero.fitted_offsets)."""
    return check_choice(value, where, ZERO_MODES)


# --- structured values ------------------------------------------------------------


def svr_settings(raw: Any, where: str, base: SVRSettings) -> SVRSettings:
    """Table 2's keys; ``gamma`` or ``delta2`` (gamma = 1/(2 delta2)); ``tolerance: null``
    is fit's rule, as when not written."""
    raw = mapping(raw, where)
    for key in raw:
        if key not in SVR_KEYS:
            raise unknown(str(key), set(SVR_KEYS), where)
    if "gamma" in raw and "delta2" in raw:
        raise ConfigError(f"{where}: give either 'gamma' or 'delta2' (gamma = 1/(2 delta2)), not both")
    kw = {k: number(raw[k], f"{where}: {k}", within=SVR_RANGE) for k in SVR_KEYS
          if k in raw and not (k == "tolerance" and raw[k] is None)}
    if "tolerance" in raw and raw["tolerance"] is None:
        kw["tolerance"] = None
    if "delta2" in kw:
        kw["gamma"] = 1.0 / (2.0 * kw.pop("delta2"))
    return replace(base, **kw)


def units(raw: Any, where: str, layout: Layout) -> Units:
    """``{load: N, output: V}``, or per column: ``{load: {fx: N, mx: N·m}, output: {u1: V}}``."""
    raw = mapping(raw, where)
    loads = (*LOAD_UNITS, *(() if layout.is_default else MOMENT_UNITS))
    allowed = {"load": loads, "output": (*OUTPUT_UNITS, *loads)}  # a factory-calibrated N, N·m
    columns = {"load": layout.loads, "output": layout.outputs}
    for key in raw:
        if key not in allowed:
            raise unknown(str(key), set(allowed), where)
    kw: dict[str, Any] = {}
    for key, known in allowed.items():
        if key not in raw:
            continue
        value = raw[key]
        if isinstance(value, dict):
            for col in value:
                if col not in columns[key]:
                    raise unknown(str(col), set(columns[key]), f"{where}: {key}")
            missing = [c for c in columns[key] if c not in value]
            if missing:
                raise ConfigError(f"{where}: {key}: no unit for {', '.join(missing)}; give one "
                                  "per column, or one unit for all")
            per = tuple(value[c] for c in columns[key])
        else:
            per = (value,)
        for unit in per:
            if unit not in known:
                raise ConfigError(f"{where}: {key}: unknown unit {unit!r}; expected one of "
                                  f"{', '.join(known)}")
        if len(set(per)) == 1:
            kw[key] = per[0]
        else:  # mixed units: shown column by column, never converted as one
            kw[key] = " / ".join(dict.fromkeys(per))
            kw[f"{key}s"] = per
    return Units(**kw)


def names(raw: Any, where: str) -> tuple[str, ...]:
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


def layout_names(raw: dict, source: str) -> tuple[tuple[str, ...], tuple[str, ...]] | None:
    """``components`` and ``outputs``: N loads and each one's prime output, or M > N outputs."""
    if "components" not in raw and "outputs" not in raw:
        return None
    if "components" not in raw or "outputs" not in raw:
        given, other = ("components", "outputs") if "components" in raw else ("outputs", "components")
        raise ConfigError(f"{source}: {given} needs {other}: the prime output of each component, "
                          "in the same order")
    comps = names(raw["components"], f"{source}: components")
    outs = names(raw["outputs"], f"{source}: outputs")
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


def limits(raw: Any, where: str, outputs=VOLTAGE_COLUMNS) -> dict[str, tuple[float, float]]:
    """``{ux: [lo, hi], ...}``: the raw range of each output, in the data's units."""
    raw = mapping(raw, where)
    out = {}
    for key, pair in raw.items():
        if key not in outputs:
            raise unknown(str(key), set(outputs), where)
        if not (isinstance(pair, list | tuple) and len(pair) == 2):
            raise ConfigError(f"{where}: {key}: expected [lo, hi], found {pair!r}")
        lo, hi = (number(v, f"{where}: {key}") for v in pair)
        if not lo < hi:
            raise ConfigError(f"{where}: {key}: expected lo < hi, found [{pair[0]!r}, {pair[1]!r}]")
        out[key] = (lo, hi)
    return out


def _sensor(value: Any, where: str, s: Settings) -> dict:
    if not isinstance(value, str) or not value.strip():
        raise ConfigError(f"{where}: expected a name, found {value!r}")
    return {"sensor": value}


def _full_scale(value: Any, where: str, s: Settings) -> dict:
    labels = s.layout.labels
    fs = mapping(value, where)
    for key in fs:
        if key not in labels:
            raise unknown(str(key), set(labels), where)
    missing = [a for a in labels if a not in fs]
    if missing:
        raise ConfigError(f"{where}: missing axis {', '.join(missing)}")
    return {"full_scale": tuple(number(fs[a], f"{where}: {a}", positive=True) for a in labels)}


def _columns(value: Any, where: str, s: Settings) -> dict:
    merged = dict(s.columns)
    for key, name in mapping(value, where).items():
        if key not in s.layout.canonical:
            raise unknown(str(key), set(s.layout.canonical), where)
        if not isinstance(name, str) or not name:
            raise ConfigError(f"{where}: {key}: expected a column name, found {name!r}")
        merged[key] = name
    if len(set(merged.values())) != len(merged):
        twice = next(v for v in merged.values() if list(merged.values()).count(v) > 1)
        keys = [k for k, v in merged.items() if v == twice]
        raise ConfigError(f"{where}: two quantities map to the same file column "
                          f"('{twice}': {' and '.join(keys)})")
    return {"columns": merged}


def _scale(value: Any, where: str, s: Settings) -> dict:
    merged = dict(s.scale)
    for key, factor in mapping(value, where).items():
        if key not in merged:
            raise unknown(str(key), set(merged), where)
        v = number(factor, f"{where}: {key}")
        if v == 0:
            raise ConfigError(f"{where}: {key}: must not be 0")
        merged[key] = v
    return {"scale": merged}


def _csv(value: Any, where: str, s: Settings) -> dict:
    kw = {}
    for key, char in mapping(value, where).items():
        if key not in ("sep", "decimal"):
            raise unknown(str(key), {"sep", "decimal"}, where)
        if not isinstance(char, str) or len(char) != 1 or char in NOT_CSV \
                or (key == "decimal" and char not in ".,"):
            raise ConfigError(f"{where}: {key}: expected {CSV_CHARS[key]}, found {char!r}")
        kw[key] = char
    if kw.get("sep", ",") == kw.get("decimal", "."):
        raise ConfigError(f"{where}: sep and decimal must differ")
    return kw


def _rotation(value: Any, where: str, s: Settings) -> dict:
    rotation = parse_rotation(value, where)
    if rotation is not None and s.layout.n != 3:
        raise ConfigError(f"{where}: rotates three forces; a sensor of {s.layout.n} components "
                          "takes frame: {rotation, origin}")
    return {"rotation": rotation}


def _frame(value: Any, where: str, s: Settings) -> dict:
    return {} if value is None else {"frame": parse_frame(value, where, s.layout.n)}


def _checks(value: Any, where: str, s: Settings) -> dict:
    kw = {}
    for key, v in mapping(value, where).items():
        if key != "min_r2":
            raise unknown(str(key), {"min_r2"}, where)
        kw["min_r2"] = number(v, f"{where}: min_r2", positive=True)
    return kw


def _field(name: str, check: Callable[[Any, str], Any]) -> Callable[[Any, str, Settings], dict]:
    """A key whose value, once checked, is the Settings field of the same name."""
    return lambda value, where, s: {name: check(value, where)}


# --- the schema -------------------------------------------------------------------


@dataclass(frozen=True)
class Key:
    """One top-level config key: how it is read, its default as a reader sees it, its doc,
    and whether ``apply`` reads it from a config (True) or takes the model's."""

    name: str
    read: Callable[[Any, str, Settings], dict]  # (value, "file: key", settings so far) -> fields
    default: str
    doc: str
    applies: bool = False


SCHEMA: tuple[Key, ...] = (
    Key("components", lambda v, w, s: {}, "x, y, z",
        "the sensor's N components (its load columns); with outputs", applies=True),
    Key("outputs", lambda v, w, s: {}, "ux, uy, uz",
        "each component's prime output, in the same order, or M > N outputs", applies=True),
    Key("sensor", _sensor, "paper-3axis", "the sensor's name"),
    Key("full_scale", _full_scale, "{x: 100, y: 100, z: 150}",
        "the full-scale load of each component, in the data's load unit (> 0)"),
    Key("min_repetitions", _field("min_repetitions", Whole(1)), "6",
        "repetitions a calibration set must have (a whole number >= 1)"),
    Key("columns", _columns, "each quantity's own name",
        "the file column of each quantity", applies=True),
    Key("scale", _scale, "1 for every column",
        "a factor applied to each column's values (not 0)", applies=True),
    Key("csv", _csv, '{sep: ",", decimal: "."}', "the CSV separator and decimal mark",
        applies=True),
    Key("svr", lambda v, w, s: {"svr": svr_settings(v, w, s.svr)}, "Table 2",
        "C, epsilon, gamma or delta2, tolerance: libsvm's epsilon-SVR (each 1e-12 .. 1e12)"),
    Key("scaling", _field("scaling", Choice(SCALINGS)), "none",
        "the SVRs' units: none (volts, Table 2) or full_scale"),
    Key("rotation", _rotation, "none", "a 3x3 rotation from the sensor to the reference frame"),
    Key("frame", _frame, "none", "six axes: {rotation, origin}, the wrench transform"),
    Key("limits", lambda v, w, s: {"limits": limits(v, w, s.layout.outputs)}, "none",
        "the raw range [lo, hi] of each output channel (the saturated status)", applies=True),
    Key("refine", _field("refine", check_refine), "0",
        f"second-order refinement steps K (0 .. {MAX_REFINE})"),
    Key("zero", _field("zero", check_zero), "rows (x, y, z) or fit",
        "how sweeps are zeroed: rows or fit"),
    Key("method", _field("method", Choice(FIT_METHODS)), "svr",
        "what fit's model decouples by: svr, linear or auto (the lower held-out error)"),
    Key("extrapolation", _field("extrapolation", check_choice), DEFAULT_EXTRAPOLATION,
        "chi beyond its calibrated range: tangent or kernel"),
    Key("units", lambda v, w, s: {"units": units(v, w, s.layout)}, "{load: N, output: V}",
        "the data's load and output units, one or per column", applies=True),
    Key("checks", _checks, "{min_r2: 0.99}", "assumption 1's R^2 below which fit warns"),
    *(Key(k, lambda v, w, s: {}, "none", "the certificate's statement (labinfo.py)")
      for k in sorted(LAB_KEYS)),
)
KEYS = {k.name: k for k in SCHEMA}
APPLY_KEYS = tuple(k.name for k in SCHEMA if k.applies)


def validate(raw: Any, source: str, base: Settings) -> tuple[Settings, frozenset[str]]:
    """The settings a parsed YAML document states over ``base``, and the keys it wrote.

    Unknown keys are refused with a hint; each value is checked by its :class:`Key`.
    """
    raw = mapping({} if raw is None else raw, source)
    for key in raw:
        if key not in KEYS:
            raise unknown(str(key), set(KEYS), source)
    s = base
    named = layout_names(raw, source)
    if named is not None:
        layout = Layout.named(*named)
        s = replace(s, components=named[0], outputs=named[1],
                    columns={c: c for c in layout.canonical},
                    scale={c: 1.0 for c in (*layout.loads, *layout.outputs)},
                    full_scale=(1.0,) * layout.n)
    kw: dict[str, Any] = {}
    for key in SCHEMA:
        if key.name in raw:
            kw.update(key.read(raw[key.name], f"{source}: {key.name}", s))
    if "units" in raw and "scaling" not in raw and kw["units"].output != "V":
        kw["scaling"] = "full_scale"  # Table 2's kernel width assumes outputs of order 1 V
    kw.update(lab_from_dict(raw, source))
    return replace(s, **kw), frozenset(raw)


# keys a command takes from the model that change what apply writes: refused when a
# config states them otherwise; the fit-only rest (svr, scaling, checks, ...) is warned about
CHANGES_FORCES = ("rotation", "frame", "refine", "extrapolation", "full_scale")


# the keys each command that takes a model and a config (-c) reads from the config; every
# other key is the model's own: refused (CHANGES_FORCES) or warned about when it differs.
# validate scores its set in the config's full scale and zeroes its sweeps by its zero;
# the certificate reads the very set the model was fitted on (zero may be left unsaid,
# certificate_doc.check_matches) and states the lab's keys
READS = {
    "apply": APPLY_KEYS,
    "validate": (*APPLY_KEYS, "full_scale", "zero"),
    "certificate": (*APPLY_KEYS, "sensor", "full_scale", "zero", *sorted(LAB_KEYS)),
}
# keys fit's own options state over its config (--C .. --tolerance, --scaling, --refine,
# --method, --extrapolation, --tune): the config fit was given may say otherwise than the
# model it made.  The certificate decouples nothing, so for it they are the model's own
# choice: warned about, never refused (issue 33: the config fit used is the one it takes).
FIT_OPTIONS = ("svr", "scaling", "refine", "method", "extrapolation")


def unused_keys(settings: Settings, model_settings: Settings, command: str = "apply") -> list[str]:
    """The keys a config wrote that ``command`` does not read from a config (:data:`READS`;
    the model's own) and whose values differ from the model's."""
    out = []
    for name in sorted(settings.given - set(READS[command])):
        if name == "svr":
            mine, theirs = settings.svr, model_settings.svr
            fields = ["C", "epsilon", "gamma"] + ([] if mine.tolerance is None else ["tolerance"])
            same = all(getattr(mine, f) == getattr(theirs, f) for f in fields)
        elif name == "zero":  # a model leaves unsaid the zero rows it used by default
            same = settings.zero_method == model_settings.zero_method
        else:
            attr = "min_r2" if name == "checks" else "lab" if name in LAB_KEYS else name
            same = getattr(settings, attr) == getattr(model_settings, attr)
        if not same:
            out.append(name)
    return out


def _unused(names: list[str], command: str) -> str:
    uses = ("takes the model's own (fit's options may have stated them over its config)"
            if command == "certificate" else "decouples with the model's own settings")
    return (f"the config's {', '.join(names)} differ{'s' if len(names) == 1 else ''} from the "
            f"model's: {command} {uses} and reads only {', '.join(READS[command])} from a config")


def _refused(command: str) -> set[str]:
    """The keys ``command`` refuses when a config states them otherwise than the model."""
    return set(CHANGES_FORCES) - (set(FIT_OPTIONS) if command == "certificate" else set())


def refuse_unused(settings: Settings, model_settings: Settings, command: str = "apply") -> None:
    """Refuse a config that states a key changing the forces (:data:`CHANGES_FORCES`)
    otherwise than the model: ``apply -c rot.yaml`` with a rotation the model lacks
    decoupled without it, in silence."""
    names = [n for n in unused_keys(settings, model_settings, command) if n in _refused(command)]
    if names:
        raise ConfigError(f"{_unused(names, command)}; refit with this config, or leave "
                          f"{' and '.join(names)} out")


def unused_warning(settings: Settings, model_settings: Settings, command: str = "apply") -> list[str]:
    """The warning for fit-only keys a config states otherwise than the model (not used)."""
    names = [n for n in unused_keys(settings, model_settings, command) if n not in _refused(command)]
    return [f"{_unused(names, command)}; not used here"] if names else []
