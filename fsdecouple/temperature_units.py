"""The config's temperature keys: ``columns: {temperature: <header>}`` and
``units: {temperature: degC | K | degF}`` (issue 31; core/temperature.py).

Kept apart from config.py's other keys: :func:`split` takes them out of the raw
mapping before the rest is validated, and :func:`to_celsius` is the one conversion
of a temperature column (calibration, log, ``apply --temperature``) to degrees
Celsius, the unit a fitted model's temperature terms are in.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .errors import ConfigError

KEY = "temperature"
# the unit's spellings, and (scale, offset) to degC: T_C = scale * (T + offset)
TEMPERATURE_UNITS = {"degC": (1.0, 0.0), "K": (1.0, -273.15), "degF": (5.0 / 9.0, -32.0)}
ALIASES = {"°C": "degC", "C": "degC", "celsius": "degC", "kelvin": "K", "°F": "degF",
           "F": "degF", "fahrenheit": "degF"}
MODEL_UNIT = "degC"


def split(raw: dict, source: str) -> tuple[dict, dict[str, Any]]:
    """``raw`` without the temperature keys, and the Settings fields they give."""
    kw: dict[str, Any] = {}
    out = dict(raw)
    cols = out.get("columns")
    if isinstance(cols, dict) and KEY in cols:
        cols = dict(cols)
        name = cols.pop(KEY)
        if not isinstance(name, str) or not name:
            raise ConfigError(f"{source}: columns: temperature: expected a column name, "
                              f"found {name!r}")
        kw["temperature_column"] = name
        out["columns"] = cols
    units = out.get("units")
    if isinstance(units, dict) and KEY in units:
        units = dict(units)
        unit = units.pop(KEY)
        kw["temperature_unit"] = check_unit(unit, f"{source}: units: temperature")
        if units:
            out["units"] = units
        else:
            del out["units"]
    return out, kw


def check_unit(unit: Any, where: str) -> str:
    """``degC``, ``K`` or ``degF`` (°C, °F, C, F, celsius, kelvin, fahrenheit read as such)."""
    name = ALIASES.get(unit, unit) if isinstance(unit, str) else unit
    if name not in TEMPERATURE_UNITS:
        raise ConfigError(f"{where}: unknown unit {unit!r}; expected one of "
                          f"{', '.join(TEMPERATURE_UNITS)}")
    return name


def to_celsius(values, unit: str) -> np.ndarray:
    """Temperatures in ``unit`` as degrees Celsius."""
    scale, offset = TEMPERATURE_UNITS[unit]
    v = np.asarray(values, dtype=float)
    return v if (scale, offset) == (1.0, 0.0) else scale * (v + offset)


def add_to_dict(d: dict, column: str | None, unit: str) -> None:
    """Put the keys back where a config writes them (the model file's settings)."""
    d.pop("temperature_column", None)
    d.pop("temperature_unit", None)
    if column is None:
        return
    d["columns"] = {**d.get("columns", {}), KEY: column}
    d["units"] = {**d.get("units", {}), KEY: unit}
