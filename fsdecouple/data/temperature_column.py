"""``init``'s guess of a temperature column (issue 31): a header named as a temperature
(``temp``, ``temperature``, ``T [°C]``, ``temp_C``, ``thermistor``) and its unit."""

from __future__ import annotations

import re

from .guesses import Guess, shown

# a temperature column (issue 31): its name once units and separators are stripped, and
# the unit a header may carry ([°C], _C, (K), degF)
_TEMPERATURE = re.compile(r"(?:t|temp|temperature|thermistor)(?:_?(c|k|f|degc|degf))?")
_TEMPERATURE_UNITS = {"c": "degC", "°c": "degC", "degc": "degC", "celsius": "degC", "k": "K",
                      "kelvin": "K", "f": "degF", "°f": "degF", "degf": "degF"}


def with_temperature(guess: Guess, names: list[str]) -> Guess:
    """``guess`` with ``columns: {temperature: ...}`` and its unit when an unmapped header is
    a temperature (``temp``, ``temperature``, ``T [°C]``, ``temp_C``, ``thermistor``)."""
    for item in list(guess.ignored):
        if item.reason != "not a known quantity":
            continue
        raw = item.name.strip()
        m = re.fullmatch(r"(.*?)\s*[\[(]\s*([^\])]*)\s*[\])]\s*", raw)
        base, unit = (m.group(1), m.group(2)) if m else (raw, "")
        key = re.sub(r"[\s\-.]+", "", base.lower())
        hit = _TEMPERATURE.fullmatch(key)
        if not hit:
            continue
        unit = _TEMPERATURE_UNITS.get(unit.strip().lower() or (hit.group(1) or "c"), "degC")
        guess.columns["temperature"] = item.name
        guess.units["temperature"] = unit
        guess.reasons["temperature"] = (f"{shown(item.name)}: named as a temperature, read in "
                                        f"{unit} (the drift terms are fitted when the set spans "
                                        ">= 5 K)")
        guess.keys = (*guess.keys, "temperature")
        guess.ignored.remove(item)
        break
    return guess
