"""A 3-axis sensor that drifts with temperature (``simulate --temperature``, issue 31).

The paper's sensor (:class:`~fsdecouple.sim.simulate.SimulatedSensor`) with, per output
channel i, a zero offset z_i, an offset drift b_i (0.06-0.07 % of full-scale output per
K) and a gain drift g_i (90-200 ppm/K) about T0 = 25 degC in ATI's form, plus a small
quadratic offset drift q_i (T - T0)^2 that the linear form cannot capture:

    u_i(T) = (1 + g_i dT) (z_i + s_i(F)) + b_i dT + q_i dT^2,    dT = T - T0,

s(F) the sensor's zero-corrected outputs (eq. 1-3).  The calibration is the paper's
grid with its repetitions at 15, 25 and 35 degC; the log drifts through 10-40 degC
after a tare at 25 degC, and its twin holds 25 degC with the same loads and noise.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..axes import AXES, FORCE_COLUMNS, VOLTAGE_COLUMNS
from ..core.temperature import correct
from ..files.outputs import atomic_files, check_output
from .simulate import PAPER_GRIDS, SimulatedSensor, write_csv

T0 = 25.0  # [degC]
CALIBRATION_TEMPERATURES = (15.0, 25.0, 35.0)  # [degC]
LOG_RANGE = (10.0, 40.0)  # [degC]
OFFSET_DRIFT = (6e-4, 7e-4)  # of full-scale output per K
GAIN_DRIFT = (90e-6, 200e-6)  # per K
QUADRATIC = 1.5e-6  # of full-scale output per K^2: 0.034 % F.S. at 15 K from T0
TEMPERATURE_NOISE = 0.02  # [K] of the thermometer


@dataclass(frozen=True)
class ThermalSensor:
    """The drifting sensor's truth; ``seed`` draws its z, b, g and q."""

    base: SimulatedSensor = field(default_factory=SimulatedSensor)
    seed: int = 0

    def _draw(self):
        rng = np.random.default_rng([self.seed, 31])
        n = self.base.layout.n
        u_fs = self.base.full_scale_output
        sign = rng.choice((-1.0, 1.0), size=(3, n))
        z = rng.uniform(-0.05, 0.05, n)
        b = sign[0] * rng.uniform(*OFFSET_DRIFT, n) * u_fs
        g = sign[1] * rng.uniform(*GAIN_DRIFT, n)
        q = sign[2] * QUADRATIC * u_fs
        return z, b, g, q

    @property
    def truth(self) -> dict[str, np.ndarray]:
        z, b, g, q = self._draw()
        return {"z": z, "b": b, "g": g, "q": q}

    def raw(self, s: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Raw outputs (n, N) of zero-corrected outputs ``s`` at temperatures ``t`` [degC]."""
        z, b, g, q = self._draw()
        dt = np.asarray(t, dtype=float)[:, None] - T0
        return (1.0 + g * dt) * (z + s) + b * dt + q * dt ** 2

    def at_t0(self, raw: np.ndarray, t: np.ndarray) -> np.ndarray:
        """The true linear terms undone: outputs at T0, zero offset included (the floor's
        correction; the quadratic drift stays, as in any linear compensation)."""
        _, b, g, _ = self._draw()
        return correct(raw, t, T0, b, g)

    def floor(self, raw: np.ndarray, t: np.ndarray, tare_rows: int) -> np.ndarray:
        """Loads decoupled with the true coupling and the true temperature terms, tared on the
        first ``tare_rows`` rows (ATIDAQ's bias): the floor of any fitted model."""
        u0 = self.at_t0(raw, t)
        return self.base.solve(u0 - u0[:tare_rows].mean(axis=0))


def thermal_calibration(sensor: ThermalSensor, repetitions: int = 6, seed: int = 0) -> pd.DataFrame:
    """The paper's grid, repetition r at CALIBRATION_TEMPERATURES[(r - 1) % 3]; each row's
    temperature drifts by up to 0.2 K along its sweep and is read with thermometer noise."""
    rng = np.random.default_rng([seed, 32])
    base = sensor.base
    rows = []
    for rep in range(1, repetitions + 1):
        level = CALIBRATION_TEMPERATURES[(rep - 1) % len(CALIBRATION_TEMPERATURES)]
        for a, axis in enumerate(AXES):
            loads = PAPER_GRIDS[a]
            f = np.zeros((loads.size, 3))
            f[:, a] = loads
            t = level + np.linspace(0.0, rng.uniform(-0.2, 0.2), loads.size)
            u = sensor.raw(base.voltages(f), t) + rng.normal(0.0, base.noise, size=f.shape)
            t_read = t + rng.normal(0.0, TEMPERATURE_NOISE, size=t.size)
            for i in range(loads.size):
                rows.append((rep, axis, *f[i], *u[i], t_read[i]))
    return pd.DataFrame(rows, columns=["repetition", "axis", *FORCE_COLUMNS, *VOLTAGE_COLUMNS,
                                       "temperature"])


def thermal_log(sensor: ThermalSensor, n: int = 6000, tare_rows: int = 200, seed: int = 0):
    """A combined-load log drifting through LOG_RANGE after ``tare_rows`` unloaded rows at T0,
    and its twin held at T0 (same loads and noise).  Returns (log, twin, true forces, T)."""
    rng = np.random.default_rng([seed, 33])
    base = sensor.base
    x = np.arange(n) / n
    f = np.zeros((n, 3))
    moving = np.arange(n) >= tare_rows
    xm = (x[moving] - x[tare_rows]) * n / 100.0  # in "seconds" of 100 rows
    ramp = np.minimum(1.0, xm / 2.0)
    f[moving, 0] = 70.0 * ramp * np.sin(2 * np.pi * 0.07 * xm)
    f[moving, 1] = 60.0 * ramp * np.sin(2 * np.pi * 0.11 * xm + 1.0)
    f[moving, 2] = -75.0 * ramp * (1.0 - 0.8 * np.cos(2 * np.pi * 0.05 * xm))
    # T0 for the tare, then down to 10, up to 40 and back: every temperature of the range
    lo, hi = LOG_RANGE
    phase = np.clip((np.arange(n) - tare_rows) / max(n - tare_rows, 1), 0.0, 1.0)
    t = np.interp(phase, [0.0, 0.25, 0.75, 1.0], [T0, lo, hi, T0])
    s = base.voltages(f)
    noise = rng.normal(0.0, base.noise, size=f.shape)
    t_noise = rng.normal(0.0, TEMPERATURE_NOISE, size=n)
    log = sensor.raw(s, t) + noise
    twin = sensor.raw(s, np.full(n, T0)) + noise
    return log, twin, f, t + t_noise


def write_thermal(out: Path, *, seed: int, repetitions: int, force: bool,
                  sensor: SimulatedSensor | None = None) -> list[Path]:
    """``simulate --temperature``: calibration/rep*.csv (with a temperature column),
    task_voltages.csv (drifting 10-40 degC), task_voltages_25C.csv (its twin at 25 degC),
    task_forces.csv, sensor.yaml (columns: {temperature: ...}) and truth.json."""
    thermal = ThermalSensor(sensor or SimulatedSensor(), seed)
    names = [*(Path("calibration") / f"rep{r}.csv" for r in range(1, repetitions + 1)),
             Path("task_voltages.csv"), Path("task_voltages_25C.csv"), Path("task_forces.csv"),
             Path("sensor.yaml"), Path("truth.json")]
    for name in names:
        if (out / name).parent.is_dir():
            check_output(out / name, force=force)
    table = thermal_calibration(thermal, repetitions, seed)
    log, twin, f, t = thermal_log(thermal, seed=seed)
    volt_fmt = {c: "%.7f" for c in VOLTAGE_COLUMNS}
    force_fmt = {c: "%.3f" for c in FORCE_COLUMNS}
    idx = np.arange(len(f)) / 100.0
    truth = thermal.truth
    with atomic_files(force=force) as group:
        for rep, g in table.groupby("repetition"):
            write_csv(g.drop(columns="repetition"), out / "calibration" / f"rep{rep}.csv",
                      {**force_fmt, **volt_fmt, "temperature": "%.3f"}, group)
        for u, name in ((log, "task_voltages.csv"), (twin, "task_voltages_25C.csv")):
            frame = pd.DataFrame({"t": idx, **{c: u[:, i] for i, c in enumerate(VOLTAGE_COLUMNS)},
                                  "temperature": t if name == "task_voltages.csv" else T0})
            write_csv(frame, out / name, {"t": "%.2f", **volt_fmt, "temperature": "%.3f"}, group)
        forces = pd.DataFrame({"t": idx, **{c: f[:, i] for i, c in enumerate(FORCE_COLUMNS)}})
        write_csv(forces, out / "task_forces.csv", {"t": "%.2f", **force_fmt}, group)
        with group.open(out / "sensor.yaml") as fh:
            fh.write("# simulate --temperature: the paper's sensor, drifting with temperature\n"
                     "sensor: paper-3axis-thermal\n"
                     "columns: {temperature: temperature}\n"
                     "units: {temperature: degC}\n")
        with group.open(out / "truth.json") as fh:
            json.dump({"t0": T0, "unit": "degC", "output_unit": "V",
                       **{k: dict(zip(VOLTAGE_COLUMNS, map(float, v), strict=True))
                          for k, v in truth.items()},
                       "note": "u = (1 + g dT)(z + s(F)) + b dT + q dT^2, dT = T - t0"},
                      fh, indent=1, sort_keys=True)
            fh.write("\n")
    return [out / n for n in names]
