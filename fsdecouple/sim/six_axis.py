"""A simulated six-axis force/torque sensor: the coupling error model for N = 6.

Components ``fx fy fz`` [N] and ``mx my mz`` [N·m], each with its own prime
output ``u1 .. u6`` [V].  Every one of the 30 pairs couples by eq. (3): a smooth
nonlinear element (:func:`fsdecouple.sim.simulate._shape`) of 0.2-1.75 % of the output's
full scale, drawn from the seed, so each seed is another sensor.  Calibration: one
sweep per component and repetition, 21 loads from -FS to +FS (the zero row in the
middle), Gaussian noise and a zero offset per sweep, as the 3-axis simulator.
The task log loads all six components at once (a wrench), with its true loads.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..axes import Layout
from ..errors import InputError
from ..files.outputs import atomic_files, check_output
from .simulate import MAX_REPETITIONS, SimulatedSensor, check_count, one_set, with_coupling, write_csv

COMPONENTS = ("fx", "fy", "fz", "mx", "my", "mz")
OUTPUTS = ("u1", "u2", "u3", "u4", "u5", "u6")
FULL_SCALE = (100.0, 100.0, 200.0, 5.0, 5.0, 5.0)  # [N], [N·m]
LOAD_UNITS = ("N", "N", "N", "N·m", "N·m", "N·m")
COUPLING = (0.002, 0.0175)  # peak of each coupling element, fraction of its output's F.S.
POINTS = 21  # loads per sweep, -FS .. +FS, the zero-load row among them
TARE_ROWS = 200

CONFIG = """\
# A simulated six-axis force/torque sensor (fsdecouple simulate --components 6).
sensor: {sensor}

# The load components, and the prime output of each, in the same order.
components: [fx, fy, fz, mx, my, mz]
outputs: [u1, u2, u3, u4, u5, u6]

# Full-scale loads: forces in N, moments in N·m.
full_scale: {{fx: 100, fy: 100, fz: 200, mx: 5, my: 5, mz: 5}}
units:
  load: {{fx: N, fy: N, fz: N, mx: N·m, my: N·m, mz: N·m}}
  output: V

min_repetitions: 6
"""


def six_axis_sensor(seed: int = 0, coupling: tuple[float, float] = COUPLING) -> SimulatedSensor:
    """A six-axis sensor drawn from ``seed``: slopes, 30 coupling amplitudes and shapes."""
    rng = np.random.default_rng([6, seed])
    layout = Layout.named(COMPONENTS, OUTPUTS)
    u_fs = rng.uniform(1.0, 2.0, size=6)  # full-scale outputs [V]
    amplitude = rng.uniform(*coupling, size=(6, 6))
    np.fill_diagonal(amplitude, 0.0)
    shapes = {}
    for name in layout.chi_names:
        # a linear, a quadratic and a wave part, each of either sign: never flat
        mag = rng.uniform((0.2, 0.2, 0.1), (1.0, 0.8, 0.5))
        shapes[name] = tuple(float(v) for v in mag * rng.choice((-1.0, 1.0), size=3))
    return SimulatedSensor(
        inverse_slopes=tuple(float(v) for v in np.asarray(FULL_SCALE) / u_fs),
        full_scale=FULL_SCALE,
        amplitude=tuple(tuple(float(v) for v in row) for row in amplitude),
        shapes=shapes,
        load_span=((-1.0, 1.0),) * 6,
        layout=layout,
    )


def simulate_calibration(sensor: SimulatedSensor, repetitions: int = 6,
                         seed: int = 0) -> pd.DataFrame:
    """The long calibration table (``repetition, axis, fx .. mz, u1 .. u6``), raw outputs."""
    rng = np.random.default_rng([60, seed])
    layout = sensor.layout
    frames = []
    for rep in range(1, repetitions + 1):
        for a, label in enumerate(layout.labels):
            f = np.zeros((POINTS, layout.n))
            f[:, a] = np.linspace(-1.0, 1.0, POINTS) * sensor.full_scale[a]
            offset = rng.uniform(-0.05, 0.05, size=layout.n)
            u = sensor.voltages(f) + offset + rng.normal(0.0, sensor.noise, size=f.shape)
            frame = pd.DataFrame({"repetition": rep, "axis": label}, index=range(POINTS))
            frame[list(layout.loads)] = f
            frame[list(layout.outputs)] = u
            frames.append(frame)
    return pd.concat(frames, ignore_index=True)


def simulate_task(sensor: SimulatedSensor, n: int = 3000, rate: float = 1000.0,
                  tare_rows: int = TARE_ROWS, seed: int = 0) -> tuple[pd.DataFrame, pd.DataFrame]:
    """A combined-load log: every component loaded at once (30-60 % F.S.), its true loads.

    The first ``tare_rows`` rows are unloaded (``apply --tare``).
    """
    rng = np.random.default_rng([61, seed])
    layout = sensor.layout
    t = np.arange(n) / rate
    tm = np.clip(t - tare_rows / rate, 0.0, None)
    ramp = np.minimum(1.0, tm / 0.2) * (np.arange(n) >= tare_rows)
    amp = rng.uniform(0.3, 0.6, size=layout.n) * np.asarray(sensor.full_scale)
    freq, phase = rng.uniform(0.3, 1.5, size=layout.n), rng.uniform(0, 2 * np.pi, size=layout.n)
    f = amp * ramp[:, None] * np.sin(2 * np.pi * freq * tm[:, None] + phase)
    offset = rng.uniform(-0.05, 0.05, size=layout.n)
    u = sensor.voltages(f) + offset + rng.normal(0.0, sensor.noise, size=f.shape)
    volts = pd.DataFrame({"t": t, **{c: u[:, k] for k, c in enumerate(layout.outputs)}})
    loads = pd.DataFrame({"t": t, **{c: f[:, k] for k, c in enumerate(layout.loads)}})
    return volts, loads


def write_six_axis(out: str | Path, *, seed: int = 0, repetitions: int = 6, force: bool = False,
                   sensor: SimulatedSensor | None = None, coupling: float | None = None,
                   gross_error=None) -> list[Path]:
    """``OUT/calibration/rep1.csv ..``, ``task_voltages.csv``, ``task_forces.csv`` and
    ``sensor.yaml`` (the config to read them with); all files or none.

    ``coupling`` sets every coupling function's peak to that fraction of its
    output's full scale (:func:`fsdecouple.sim.simulate.with_coupling`); default: the
    seed's own amplitudes, 0.2-1.75 %.  ``gross_error``
    (:class:`fsdecouple.data.calibration.GrossError`, its axis a component) moves one
    calibration point, as for three axes (Section 4.4).
    """
    out = Path(out)
    check_count(seed, "seed", 0)
    check_count(repetitions, "repetitions", 1, MAX_REPETITIONS)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: is a file, expected a directory to write into")
    sensor = sensor or six_axis_sensor(seed)
    if coupling is not None:
        sensor = with_coupling(sensor, coupling)
    if sensor.layout.n != 6:
        raise InputError("write_six_axis: the sensor must have six components")
    targets = [*(out / "calibration" / f"rep{r}.csv" for r in range(1, repetitions + 1)),
               out / "task_voltages.csv", out / "task_forces.csv", out / "sensor.yaml"]
    for path in targets:
        if path.parent.is_dir():  # all or nothing: refuse before the first file is written
            check_output(path, force=force)
    table = simulate_calibration(sensor, repetitions, seed)
    layout = sensor.layout
    if gross_error is not None:
        table = gross_error.apply(table, layout)
    volt_fmt = {c: "%.7f" for c in layout.outputs}
    load_fmt = {c: "%.6f" for c in layout.loads}
    volts, loads = simulate_task(sensor, seed=seed)
    with one_set(out, repetitions, force), atomic_files(force=force) as group:
        for rep, g in table.groupby("repetition"):
            write_csv(g.drop(columns="repetition"), out / "calibration" / f"rep{rep}.csv",
                       {**load_fmt, **volt_fmt}, group)
        write_csv(volts, out / "task_voltages.csv", {"t": "%.3f", **volt_fmt}, group)
        write_csv(loads, out / "task_forces.csv", {"t": "%.3f", **load_fmt}, group)
        with group.open(out / "sensor.yaml") as fh:
            fh.write(CONFIG.format(sensor=f"sim-6axis-seed{seed}"))
    return targets
