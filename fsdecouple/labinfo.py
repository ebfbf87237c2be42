"""What a calibration certificate states besides the data: the sensor's serial number,
the reference standard and its uncertainty, and the environment.

Read from the config's top-level keys ``serial``, ``reference``,
``reference_uncertainty`` and ``environment`` (kept apart from ``config.py``, which
holds the keys every command needs).  Only ``reference_uncertainty`` enters a figure:
the reference load's contribution to the uncertainty budget (EURAMET cg-4).
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field
from typing import Any

from .errors import ConfigError

# The default relative expanded uncertainty (k = 2) of the reference loads [%]:
# 0.05 % is what ISO 376:2011 (Table 3) allows the calibration forces of a class 1
# calibration.  A lab states its own (deadweights are usually 0.002 %, a reference
# transducer 0.01 % to 0.05 %); an unstated reference must not look better than that.
DEFAULT_REFERENCE_UNCERTAINTY = 0.05
LAB_KEYS = {"serial", "reference", "reference_uncertainty", "environment", "creep", "drift"}
CREEP_KEYS = {"column"}


@dataclass(frozen=True)
class LabInfo:
    """The certificate's statements about the calibration, not about the data.

    ``reference_uncertainty``: relative expanded uncertainty (k = 2) of the applied
    loads [%]; ``environment``: free text per quantity, e.g. ``temperature: 21.0 °C``.
    """

    serial: str | None = None
    reference: str | None = None
    reference_uncertainty: float = DEFAULT_REFERENCE_UNCERTAINTY
    environment: dict[str, str] = field(default_factory=dict)
    # issue 33: the time column of creep readings (ISO 376 c), and the relative change
    # of the sensor between calibrations for the budget's drift term [%]
    creep_column: str | None = None
    drift: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """The config keys that differ from the defaults (model files without them keep their bytes)."""
        d: dict[str, Any] = {}
        if self.serial is not None:
            d["serial"] = self.serial
        if self.reference is not None:
            d["reference"] = self.reference
        if self.reference_uncertainty != DEFAULT_REFERENCE_UNCERTAINTY:
            d["reference_uncertainty"] = self.reference_uncertainty
        if self.environment:
            d["environment"] = dict(self.environment)
        if self.creep_column is not None:
            d["creep"] = {"column": self.creep_column}
        if self.drift is not None:
            d["drift"] = self.drift
        return d


def _text(value: Any, where: str) -> str:
    if isinstance(value, bool) or not isinstance(value, str | int | float) or not str(value).strip():
        raise ConfigError(f"{where}: expected text, found {value!r}")
    return str(value)


def lab_from_dict(raw: dict, source: str) -> dict[str, LabInfo]:
    """``{"lab": LabInfo}`` from a config's top-level keys, or ``{}`` if it has none of them."""
    if not LAB_KEYS & set(raw):
        return {}
    kw: dict[str, Any] = {}
    for key in ("serial", "reference"):
        if key in raw:
            kw[key] = _text(raw[key], f"{source}: {key}")
    if "reference_uncertainty" in raw:
        v = raw["reference_uncertainty"]
        where = f"{source}: reference_uncertainty"
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise ConfigError(f"{where}: expected a number [% at k = 2], found {v!r}")
        if not 0 < v < 100:  # no reference force is known exactly (ISO 376, Table 3)
            raise ConfigError(f"{where}: expected a relative expanded uncertainty greater than 0 "
                              f"and below 100 [% at k = 2], found {v!r}")
        kw["reference_uncertainty"] = float(v)
    if "environment" in raw:
        env = raw["environment"]
        if not isinstance(env, dict):
            raise ConfigError(f"{source}: environment: expected a mapping such as "
                              f"{{temperature: 21.0 °C}}, found {env!r}")
        kw["environment"] = {str(k): _text(v, f"{source}: environment: {k}") for k, v in env.items()}
    if "creep" in raw:
        kw["creep_column"] = _creep(raw["creep"], f"{source}: creep")
    if "drift" in raw:
        v = raw["drift"]
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v < 0:
            raise ConfigError(f"{source}: drift: expected the relative change of the sensor between "
                              f"two calibrations, a number >= 0 [%], found {v!r}")
        kw["drift"] = float(v)
    return {"lab": LabInfo(**kw)}


def _creep(value: Any, where: str) -> str:
    """``creep: {column: <time header>}``: the column dating each reading [s]."""
    if not isinstance(value, dict):
        raise ConfigError(f"{where}: expected a mapping such as {{column: time}}, found {value!r}")
    for key in value:
        if key not in CREEP_KEYS:
            hint = difflib.get_close_matches(str(key), sorted(CREEP_KEYS), n=1)
            raise ConfigError(f"{where}: unknown key '{key}'"
                              + (f" (did you mean '{hint[0]}'?)" if hint else "") + "; allowed: column")
    if "column" not in value:
        raise ConfigError(f"{where}: expected 'column', the header of the time column [s]")
    return _text(value["column"], f"{where}: column").strip()
