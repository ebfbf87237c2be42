"""The data's own units: names, checks and load conversions.

fsdecouple computes in the data's units as read (after the config's ``scale:``)
and never in absolute volts: every tolerance is a fraction of a full scale (the
full-scale load F_FS or the full-scale output |k| F_FS), so volts, millivolts
and ADC counts give the same results.  Units are labels for display, plus the
load conversions of ``apply --unit``.
"""

from __future__ import annotations

from dataclasses import dataclass

# One unit of each load unit in newtons (gf and kgf: standard gravity, 9.80665 m/s^2;
# lbf: the avoirdupois pound-force).
LOAD_UNITS = {"N": 1.0, "kN": 1000.0, "gf": 9.80665e-3, "kgf": 9.80665, "lbf": 4.4482216152605}
OUTPUT_UNITS = ("V", "mV", "uV", "count", "mV/V")


@dataclass(frozen=True)
class Units:
    """The unit of the loads and of the sensor outputs in the data files."""

    load: str = "N"
    output: str = "V"

    def slope(self) -> str:
        """The unit of k (eq. 2): output per load."""
        return f"{self.output}/{self.load}"

    def inverse_slope(self) -> str:
        """The unit of 1/k (eq. 13): load per output."""
        return f"{self.load}/{self.output}"


def load_factor(from_unit: str, to_unit: str) -> float:
    """Multiply loads in ``from_unit`` by this to get them in ``to_unit``."""
    return LOAD_UNITS[from_unit] / LOAD_UNITS[to_unit]


def output_display(unit: str) -> tuple[float, str]:
    """(factor, unit) to show small output figures such as zero offsets.

    Volts are shown in mV (offsets are a few mV); every other unit as it is.
    """
    return (1e3, "mV") if unit == "V" else (1.0, unit)
