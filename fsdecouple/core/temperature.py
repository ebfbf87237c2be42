"""Per-channel temperature correction of the outputs, before eq. (11).

ATI's form: an output i drifts in offset by b_i and in gain by g_i per unit of
temperature about a reference T0,

    u_i(T) = (1 + g_i (T - T0)) u_i(T0) + b_i (T - T0),

so the output at the reference temperature is

    u_i(T0) = (u_i - b_i (T - T0)) / (1 + g_i (T - T0)).

ATI's DAQ library (ATIDAQ, ftrt.c) writes the same correction with the
calibration file's slopes, G_c = (G + BS_i (T - T0)) / (1 - GS_i (T - T0)) with
T0 the file's ``Thermistor`` value: BS = -b, GS = -g.  T is whatever the
temperature channel reads (a thermistor voltage for ATI, degrees for a fitted
model); b is in output units per that unit, g per that unit.

A zero (``apply --zero``/``--tare``) taken at temperature T_z is corrected the
same way and subtracted after: u - u_zero becomes
``correct(u, T) - correct(u_zero, T_z)``, as ATIDAQ's bias does.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


def correct(u, t, t0: float, b, g) -> np.ndarray:
    """Outputs at the reference temperature, u_i(T0) [output unit].

    Parameters
    ----------
    u : array_like, shape (n, M')
        Outputs as read [output unit], one column per corrected channel.
    t : array_like, shape (n,)
        Temperature of each row [temperature unit].
    t0 : float
        Reference temperature T0 [temperature unit].
    b, g : array_like, shape (M',)
        Offset drift [output unit / temperature unit] and gain drift [1 / temperature unit].
    """
    dt = np.asarray(t, dtype=float)[..., None] - t0
    return (np.asarray(u, dtype=float) - np.asarray(b, float) * dt) / (1.0 + np.asarray(g, float) * dt)


@dataclass(frozen=True)
class TemperatureTerms:
    """A model's temperature correction: which output is the temperature, T0, b_i, g_i.

    Attributes
    ----------
    channel : int
        Index of the temperature among the model's outputs (its matrix column is 0).
    t0 : float
        Reference temperature T0 [``unit``].
    b, g : ndarray, shape (M,)
        Offset drift [output unit / ``unit``] and gain drift [1 / ``unit``] per output;
        0 for the temperature channel itself.
    unit : str
        The temperature channel's unit (``V`` for an ATI thermistor).
    """

    channel: int
    t0: float
    b: np.ndarray
    g: np.ndarray
    unit: str = "V"

    def zero_corrected(self, raw: np.ndarray, offsets: np.ndarray) -> np.ndarray:
        """``correct(raw, T) - correct(offsets, T_z)``; the temperature column: T - T_z.

        ``offsets`` all zero means no zero was taken: nothing is subtracted (ATIDAQ's
        bias vector before its first ``Bias``).
        """
        raw = np.asarray(raw, dtype=float)
        offsets = np.asarray(offsets, dtype=float)
        c = self.channel
        u = correct(raw, raw[:, c], self.t0, self.b, self.g)
        if offsets.any():
            u = u - correct(offsets[None, :], offsets[None, c], self.t0, self.b, self.g)
        u[:, c] = raw[:, c] - offsets[c]
        return u

    def to_dict(self, outputs) -> dict[str, Any]:
        others = [o for i, o in enumerate(outputs) if i != self.channel]
        keep = [i for i in range(len(outputs)) if i != self.channel]
        return {"output": outputs[self.channel], "t0": float(self.t0), "unit": self.unit,
                "b": dict(zip(others, map(float, self.b[keep]), strict=True)),
                "g": dict(zip(others, map(float, self.g[keep]), strict=True))}

    @classmethod
    def from_dict(cls, d: dict[str, Any], outputs) -> TemperatureTerms:
        """The model file's ``temperature``; ValueError/KeyError/TypeError when malformed."""
        outputs = list(outputs)
        channel = outputs.index(d["output"])
        b, g = np.zeros(len(outputs)), np.zeros(len(outputs))
        for i, o in enumerate(outputs):
            if i != channel:
                b[i], g[i] = float(d["b"][o]), float(d["g"][o])
        t0 = float(d["t0"])
        if not (np.isfinite(b).all() and np.isfinite(g).all() and np.isfinite(t0)):
            raise ValueError("temperature: t0, b and g must be finite")
        if set(d["b"]) != set(d["g"]) or len(d["b"]) != len(outputs) - 1:
            raise ValueError("temperature: b and g need one value per other output")
        return cls(channel, t0, b, g, str(d.get("unit", "V")))
