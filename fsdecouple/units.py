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
# lbf: the avoirdupois pound-force, klbf a thousand of them).
LOAD_UNITS = {"N": 1.0, "kN": 1000.0, "gf": 9.80665e-3, "kgf": 9.80665, "lbf": 4.4482216152605,
              "klbf": 4448.2216152605}  # klbf: ATI's klb, large sensors' calibration files
OUTPUT_UNITS = ("V", "mV", "uV", "count", "mV/V")
# Moments, for the components of a six-axis sensor (one N·m in N·m; display only:
# ``apply --unit`` converts forces of one unit, never a wrench of mixed units).
MOMENT_UNITS = {"N·m": 1.0, "Nm": 1.0, "N*m": 1.0, "N.m": 1.0, "N-m": 1.0, "N m": 1.0,
                "N·mm": 1e-3, "Nmm": 1e-3, "N·cm": 1e-2, "kN·m": 1e3,
                "kgf·m": 9.80665, "kgf·cm": 9.80665e-2, "lbf·in": 0.1129848290276167,
                "lbf·ft": 1.3558179483314004}


def unit_key(text: str) -> str:
    """A unit's spelling without case, spaces or product signs: ``N mm``, ``N·mm``, ``Nmm``
    and ``N*mm`` all read ``nmm``."""
    return "".join(c for c in text.lower() if c not in " ·⋅*.-_")


@dataclass(frozen=True)
class Units:
    """The unit of the loads and of the sensor outputs in the data files."""

    load: str = "N"
    output: str = "V"
    # one unit per component / output, when the config gives them column by column
    # (a six-axis sensor's N and N·m); empty when one unit serves all
    loads: tuple[str, ...] = ()
    outputs: tuple[str, ...] = ()
    # of a temperature column (columns: {temperature: ...}; temperature_units.py), or None
    temperature: str | None = None

    def load_of(self, a: int) -> str:
        """The unit of component a's load."""
        return self.loads[a] if self.loads else self.load

    def output_of(self, a: int) -> str:
        """The unit of output a."""
        return self.outputs[a] if self.outputs else self.output

    def to_dict(self, loads=(), outputs=()) -> dict:
        """The config's form: one unit, or a mapping by column name (``loads``, ``outputs``)."""
        return {"load": dict(zip(loads, self.loads, strict=True)) if self.loads else self.load,
                "output": dict(zip(outputs, self.outputs, strict=True)) if self.outputs
                else self.output, **({"temperature": self.temperature} if self.temperature else {})}

    def slope(self) -> str:
        """The unit of k (eq. 2): output per load."""
        return f"{self.output}/{self.load}"

    def inverse_slope(self) -> str:
        """The unit of 1/k (eq. 13): load per output."""
        return f"{self.load}/{self.output}"


def load_factor(from_unit: str, to_unit: str) -> float:
    """Multiply loads in ``from_unit`` by this to get them in ``to_unit`` (1 for the same unit,
    also a mixed one such as ``N / N·m``, which has no factor to another)."""
    return 1.0 if from_unit == to_unit else LOAD_UNITS[from_unit] / LOAD_UNITS[to_unit]


def output_display(unit: str) -> tuple[float, str]:
    """(factor, unit) to show small output figures such as zero offsets.

    Volts are shown in mV (offsets are a few mV); every other unit as it is.
    """
    return (1e3, "mV") if unit == "V" else (1.0, unit)
