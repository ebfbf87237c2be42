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
``correct(u, T) - correct(u_zero, T_z)``, as ATIDAQ's bias does.  Both are one step
of the decoupling plan (:class:`fsdecouple.core.plan.TemperatureCorrection`), which
every evaluator (numpy, tables, one vector, the C header) applies.
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
    u = np.asarray(u)
    dtype = u.dtype if u.dtype in (np.float32, np.float64) else np.dtype(float)
    u = u.astype(dtype, copy=False)  # float32 in the float header's emulation, as its C rounds
    dt = np.asarray(t).astype(dtype)[..., None] - dtype.type(t0)
    b, g = (np.asarray(v, dtype=float).astype(dtype) for v in (b, g))
    return (u - b * dt) / (dtype.type(1.0) + g * dt)


@dataclass(frozen=True)
class TemperatureTerms:
    """A model's temperature correction: where the temperature is, T0, b_i, g_i.

    Attributes
    ----------
    channel : int
        Index of the temperature among the model's inputs: one of its outputs (an ATI
        thermistor, whose matrix column is 0), or ``len(b)``, an input after the
        outputs (a fitted model's temperature column, ``external``).
    t0 : float
        Reference temperature T0 [``unit``].
    b, g : ndarray, shape (M,)
        Offset drift [output unit / ``unit``] and gain drift [1 / ``unit``] per output;
        0 for an ATI thermistor itself.
    unit : str
        The temperature's unit (``V`` for an ATI thermistor, ``degC`` for a fitted model).
    span : tuple of float, optional
        The calibrated temperatures (lo, hi) [``unit``]: beyond them a row is extrapolated.
    b_sigma, g_sigma : ndarray, shape (M,), optional
        Standard uncertainties of b and g from the fit (fitting/temperature.py).
    """

    channel: int
    t0: float
    b: np.ndarray
    g: np.ndarray
    unit: str = "V"
    span: tuple[float, float] | None = None
    b_sigma: np.ndarray | None = None
    g_sigma: np.ndarray | None = None

    @property
    def external(self) -> bool:
        """The temperature is an input after the outputs (not one of them)."""
        return self.channel >= len(self.b)

    def outside(self, t: np.ndarray) -> np.ndarray:
        """Rows (n,) whose temperature is beyond the calibrated span (none without one)."""
        t = np.asarray(t, dtype=float)
        if self.span is None:
            return np.zeros(t.shape, dtype=bool)
        lo, hi = self.span
        return (t < lo) | (t > hi)

    def to_dict(self, outputs) -> dict[str, Any]:
        outputs = list(outputs)
        keep = [i for i in range(len(outputs)) if i != self.channel]
        names = [outputs[i] for i in keep]
        d: dict[str, Any] = {"t0": float(self.t0), "unit": self.unit,
                             "b": dict(zip(names, map(float, self.b[keep]), strict=True)),
                             "g": dict(zip(names, map(float, self.g[keep]), strict=True))}
        if not self.external:
            d["output"] = outputs[self.channel]
        if self.span is not None:
            d["span"] = [float(v) for v in self.span]
        for key in ("b_sigma", "g_sigma"):
            v = getattr(self, key)
            if v is not None:
                d[key] = dict(zip(names, map(float, np.asarray(v)[keep]), strict=True))
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any], outputs) -> TemperatureTerms:
        """The model file's ``temperature``; ValueError/KeyError/TypeError when malformed."""
        outputs = list(outputs)
        channel = outputs.index(d["output"]) if "output" in d else len(outputs)
        b, g = np.zeros(len(outputs)), np.zeros(len(outputs))
        sig = {k: np.zeros(len(outputs)) for k in ("b_sigma", "g_sigma") if k in d}
        for i, o in enumerate(outputs):
            if i != channel:
                b[i], g[i] = float(d["b"][o]), float(d["g"][o])
                for k, v in sig.items():
                    v[i] = float(d[k][o])
        t0 = float(d["t0"])
        if not (np.isfinite(b).all() and np.isfinite(g).all() and np.isfinite(t0)):
            raise ValueError("temperature: t0, b and g must be finite")
        if set(d["b"]) != set(d["g"]) or len(d["b"]) != len(outputs) - (channel < len(outputs)):
            raise ValueError("temperature: b and g need one value per other output")
        span = None
        if "span" in d:
            lo, hi = (float(v) for v in d["span"])
            if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
                raise ValueError(f"temperature: span [{lo!r}, {hi!r}], expected finite lo <= hi")
            span = (lo, hi)
        return cls(channel, t0, b, g, str(d.get("unit", "V")), span,
                   sig.get("b_sigma"), sig.get("g_sigma"))
