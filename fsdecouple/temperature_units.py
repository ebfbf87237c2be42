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
DEFAULT_TEMPERATURE = "temperature"  # a file's column of this name is read without a mapping
# the unit's spellings, and (scale, offset) to degC: T_C = scale * (T + offset)
TEMPERATURE_UNITS = {"degC": (1.0, 0.0), "K": (1.0, -273.15), "degF": (5.0 / 9.0, -32.0)}
ALIASES = {"°C": "degC", "C": "degC", "celsius": "degC", "kelvin": "K", "°F": "degF",
           "F": "degF", "fahrenheit": "degF"}
MODEL_UNIT = "degC"
# [K]: two temperatures at least this far apart fit temperature terms (issue 31; the
# fitting in fitting/temperature.py, a soak file's check in data/calibration.py)
MIN_SPAN = 5.0


def config_keys(settings_from_dict):
    """Wrap config.settings_from_dict: the temperature keys taken out of ``columns:`` and
    ``units:`` before the rest is validated, and put back into the Settings after, as
    ``columns["temperature"]`` and ``units.temperature`` (degC unless given)."""
    import functools
    from dataclasses import replace

    @functools.wraps(settings_from_dict)
    def wrapped(raw: Any, source: str = "config"):
        if not isinstance(raw, dict):
            return settings_from_dict(raw, source)
        rest, kw = split(raw, source)
        settings = settings_from_dict(rest, source)
        if "column" not in kw:
            if "unit" in kw:
                raise ConfigError(f"{source}: units: temperature: no temperature column "
                                  "(columns: {temperature: ...}) to read in it")
            return settings
        taken = {v: k for k, v in settings.columns.items()}
        if kw["column"] in taken:
            raise ConfigError(f"{source}: columns: two quantities map to the same file column "
                              f"('{kw['column']}': {taken[kw['column']]} and temperature)")
        return replace(settings, columns={**settings.columns, KEY: kw["column"]},
                       units=replace(settings.units, temperature=kw.get("unit", MODEL_UNIT)))

    return wrapped


def split(raw: dict, source: str) -> tuple[dict, dict[str, Any]]:
    """``raw`` without the temperature keys, and what they give (``column``, ``unit``)."""
    kw: dict[str, Any] = {}
    out = dict(raw)
    cols = out.get("columns")
    if isinstance(cols, dict) and KEY in cols:
        cols = dict(cols)
        name = cols.pop(KEY)
        if not isinstance(name, str) or not name:
            raise ConfigError(f"{source}: columns: temperature: expected a column name, "
                              f"found {name!r}")
        kw["column"] = name
        out["columns"] = cols
    units = out.get("units")
    if isinstance(units, dict) and KEY in units:
        units = dict(units)
        kw["unit"] = check_unit(units.pop(KEY), f"{source}: units: temperature")
        if units:
            out["units"] = units
        else:
            del out["units"]
    return out, kw


def column(settings) -> str | None:
    """The temperature column's header as mapped, or None (then a column named
    DEFAULT_TEMPERATURE is read, in degC, as ``fx`` is read from a column named fx)."""
    return settings.columns.get(KEY)


def unit(settings) -> str:
    """The temperature column's unit (degC when none is given)."""
    return settings.units.temperature or MODEL_UNIT


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
