"""A synthetic 3-axis force sensor for the sample data and for tests.

The sensor follows the paper's coupling error model exactly (eq. 1-3): linear
prime voltages with the sensitivities of eq. (13), smooth nonlinear coupling
error elements of 1-3 % of full-scale output per axis pair, by superposition;
plus Gaussian noise and a zero offset per sweep.  The same model, in gram-force and
ADC counts, is the load cell of ``sample_data/loadcell`` (:func:`load_cell_sensor`),
written as a lab's spreadsheet by :mod:`fsdecouple.sim.lab`.
"""

from __future__ import annotations

import contextlib
import numbers
import os
import re
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from ..axes import AXES, DEFAULT, FORCE_COLUMNS, VOLTAGE_COLUMNS, Layout
from ..data.calibration import GrossError
from ..errors import InputError
from ..files.outputs import atomic_files, check_output
from .hysteresis import check_hysteresis, lagged, up_and_down
from .lab import write_lab_csv

# Section 3 and eq. (13)
PAPER_INVERSE_SLOPES = (75.065, 77.788, 125.17)  # [N/V]
PAPER_FULL_SCALE = (100.0, 100.0, 150.0)  # [N]
PAPER_GRIDS = (
    np.arange(-100.0, 100.0 + 1e-9, 10.0),
    np.arange(-100.0, 100.0 + 1e-9, 10.0),
    np.arange(0.0, -150.0 - 1e-9, -5.0),
)


def _shape(s: np.ndarray, c: tuple[float, float, float]) -> np.ndarray:
    """A smooth nonlinear coupling shape of the normalised load s."""
    return c[0] * s + c[1] * s * s + c[2] * np.sin(np.pi * s)


@dataclass(frozen=True)
class SimulatedSensor:
    """Ground truth for a simulated sensor.

    ``phi_ab(f_b) = amplitude[a][b] * u_FS[a] * g_ab(f_b / F_FS[b]) / max|g_ab|`` is the
    coupling function of eq. (3), a fraction ``amplitude`` of the full-scale output;
    the max is taken over ``load_span[b]``, the calibrated loads as fractions of F_FS.
    Units are the data's: N and V for the paper's sensor, gf and ADC counts for a
    load cell (:func:`load_cell_sensor`).
    """

    inverse_slopes: tuple[float, float, float] = PAPER_INVERSE_SLOPES
    full_scale: tuple[float, float, float] = PAPER_FULL_SCALE
    amplitude: tuple[tuple[float, ...], ...] = (
        (0.0, 0.021, 0.013),
        (0.027, 0.0, 0.016),
        (0.018, 0.011, 0.0),
    )
    shapes: dict[str, tuple[float, float, float]] = field(default_factory=lambda: {
        "xy": (0.7, 0.5, 0.3), "xz": (0.4, -0.6, 0.5), "yx": (-0.5, 0.8, 0.2),
        "yz": (0.9, 0.2, -0.4), "zx": (0.3, -0.4, 0.6), "zy": (-0.6, -0.5, 0.3),
    })
    noise: float = 0.0005  # [V], standard deviation per channel
    # Section 3: X and Y are loaded both ways, Z only in compression
    load_span: tuple[tuple[float, float], ...] = ((-1.0, 1.0), (-1.0, 1.0), (-1.0, 0.0))
    layout: Layout = DEFAULT  # components and chi names (six axes: simulate_six.py)
    # None: one-way sweeps, no lag; a fraction (0 too): up-and-down sweeps and a lag whose
    # way down reads that fraction of full-scale output above the way up (hysteresis.py)
    hysteresis: float | None = None

    @property
    def k(self) -> np.ndarray:
        return 1.0 / np.asarray(self.inverse_slopes)

    @property
    def full_scale_output(self) -> np.ndarray:
        return self.k * np.asarray(self.full_scale)

    def phi(self, name: str, f: np.ndarray) -> np.ndarray:
        """Coupling error element e_ab [V] caused by load f_b [N] (eq. 3)."""
        a, b = self.layout.pair(name)
        fs = self.full_scale[b]
        lo, hi = self.load_span[b]
        grid = np.linspace(lo, hi, 1 + round(1000 * (hi - lo)))
        peak = np.abs(_shape(grid, self.shapes[name])).max()
        g = _shape(np.asarray(f, dtype=float) / fs, self.shapes[name]) / peak
        return self.amplitude[a][b] * self.full_scale_output[a] * g

    def voltages(self, f: np.ndarray) -> np.ndarray:
        """Noise-free zero-corrected voltages for forces f, shape (n, N), by eq. (1)-(3)."""
        f = np.asarray(f, dtype=float).reshape(-1, self.layout.n)
        u = f * self.k
        for name in self.shapes:
            a, b = self.layout.pair(name)
            u[:, a] += self.phi(name, f[:, b])
        return u

    def outputs(self, f: np.ndarray) -> np.ndarray:
        """Noise-free outputs along a load path f (rows in time order): :meth:`voltages`
        of the loads the body feels, lagged by the sensor's hysteresis if it has one."""
        if not self.hysteresis:
            return self.voltages(f)
        f = np.asarray(f, dtype=float).reshape(-1, self.layout.n)
        return self.voltages(lagged(f, self.full_scale, self.hysteresis))

    def solve(self, u: np.ndarray, steps: int = 200) -> np.ndarray:
        """Loads whose noise-free outputs are ``u``: eq. (1) solved with the TRUE coupling.

        The floor of any decoupler (tests, benchmarks): fixed-point steps
        f = (u - sum_b phi_ab(f_b)) / k, a contraction for couplings of a few % F.S.,
        run until they no longer move a load by 1e-13 of its full scale.
        """
        u = np.asarray(u, dtype=float).reshape(-1, self.layout.n)
        f = u / self.k
        for _ in range(steps):
            e = np.zeros_like(u)
            for name in self.shapes:
                a, b = self.layout.pair(name)
                e[:, a] += self.phi(name, f[:, b])
            new = (u - e) / self.k
            done = np.abs(new - f).max(initial=0.0) <= 1e-13 * min(self.full_scale)
            f = new
            if done:
                break
        return f


def simulate_calibration(
    sensor: SimulatedSensor, repetitions: int = 6, seed: int = 0
) -> pd.DataFrame:
    """A six-repetition single-axis calibration on the paper's grid (Section 3).

    A sensor with ``hysteresis`` is swept out and back (:func:`up_and_down`), each
    sweep from no load history.  Returns the long table with raw (not
    zero-corrected) voltages.
    """
    rng = np.random.default_rng(seed)
    rows = []
    for rep in range(1, repetitions + 1):
        for a, axis in enumerate(AXES):
            loads = PAPER_GRIDS[a] if sensor.hysteresis is None else up_and_down(PAPER_GRIDS[a])
            f = np.zeros((loads.size, 3))
            f[:, a] = loads
            offset = rng.uniform(-0.05, 0.05, size=3)
            u = sensor.outputs(f) + offset + rng.normal(0.0, sensor.noise, size=f.shape)
            for i in range(loads.size):
                rows.append((rep, axis, *f[i], *u[i]))
    return pd.DataFrame(rows, columns=["repetition", "axis", *FORCE_COLUMNS, *VOLTAGE_COLUMNS])


# A small 3-axis load cell read by a 24-bit ADC: loads [gf], outputs [counts].
# These are the sensor's unknowns: they are written into no data file.
LOAD_CELL_SLOPES = (812.5, -1347.5, 415.0)  # [counts/gf], ch1 wired reversed
LOAD_CELL_FULL_SCALE = (1000.0, 1000.0, 1000.0)  # [gf]
LOAD_CELL_OFFSETS = (1.0e5, 1.0e6)  # [counts], range of |zero offset| per sweep
VALIDATION_REACH = 1.2  # validation loads go to 120 % of full scale
LAYOUTS = ("paper", "lab")


def load_cell_sensor() -> SimulatedSensor:
    """The load cell of ``sample_data/loadcell``: coupling 0.7-2.8 % F.S. per pair,
    by the paper's model, loaded by weights (positive loads only), 25 counts noise."""
    return SimulatedSensor(
        inverse_slopes=tuple(1.0 / k for k in LOAD_CELL_SLOPES),
        full_scale=LOAD_CELL_FULL_SCALE,
        amplitude=((0.0, 0.012, 0.025), (0.018, 0.0, 0.007), (0.028, 0.009, 0.0)),
        noise=25.0,
        load_span=((0.0, 1.0),) * len(AXES),
    )


def simulate_lab_calibration(
    sensor: SimulatedSensor, rng: np.random.Generator, *, levels: int = 4,
    repetitions: int = 1, reach: float = 1.0,
) -> pd.DataFrame:
    """Single-axis sweeps by weights: per sweep a zero row, then ``levels`` loads
    evenly up to ``reach`` x full scale, with its own zero offset.

    Returns the long table (``repetition, axis, fx .. uz``) with raw outputs,
    rounded to whole counts.
    """
    rows = []
    for rep in range(1, repetitions + 1):
        for a, axis in enumerate(AXES):
            # weights are whole milligrams: round so the file's loads are the true ones
            loads = np.round(reach * sensor.full_scale[a] * np.arange(levels + 1) / levels, 3)
            f = np.zeros((loads.size, 3))
            f[:, a] = loads
            sign = rng.choice((-1.0, 1.0), size=3)
            offset = sign * rng.uniform(*LOAD_CELL_OFFSETS, size=3)
            u = sensor.voltages(f) + offset + rng.normal(0.0, sensor.noise, size=f.shape)
            for i in range(loads.size):
                rows.append((rep, axis, *f[i], *np.rint(u[i])))
    return pd.DataFrame(rows, columns=["repetition", "axis", *FORCE_COLUMNS, *VOLTAGE_COLUMNS])


def simulate_task(
    sensor: SimulatedSensor, n: int = 3000, rate: float = 1000.0, tare_rows: int = 200,
    seed: int = 0, reach: float | None = None,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """A combined-load task log: all three forces non-zero at once.

    The first ``tare_rows`` rows are unloaded (for ``apply --tare``).  Returns the
    voltage log (``t, ux, uy, uz``, raw with a zero offset) and the true forces.
    ``reach``: scale the loads so each component peaks at ``reach`` x its full scale
    (1.2: loads beyond the calibrated range, for extrapolation); default: the sample
    log's loads, 60-90 % of full scale.
    """
    rng = np.random.default_rng(seed + 1_000_003)
    t = np.arange(n) / rate
    f = np.zeros((n, 3))
    moving = np.arange(n) >= tare_rows
    tm = t[moving] - t[tare_rows] if tare_rows < n else t[moving]
    ramp = np.minimum(1.0, tm / 0.2)
    f[moving, 0] = 70.0 * ramp * np.sin(2 * np.pi * 0.7 * tm)
    f[moving, 1] = 60.0 * ramp * np.sin(2 * np.pi * 1.1 * tm + 1.0)
    f[moving, 2] = -75.0 * ramp * (1.0 - 0.8 * np.cos(2 * np.pi * 0.5 * tm))
    if reach is not None:
        f *= reach * np.asarray(sensor.full_scale) / np.abs(f).max(axis=0, initial=0.0).clip(1e-300)
    offset = rng.uniform(-0.05, 0.05, size=3)
    u = sensor.outputs(f) + offset + rng.normal(0.0, sensor.noise, size=f.shape)
    volts = pd.DataFrame({"t": t, "ux": u[:, 0], "uy": u[:, 1], "uz": u[:, 2]})
    forces = pd.DataFrame({"t": t, "fx": f[:, 0], "fy": f[:, 1], "fz": f[:, 2]})
    return volts, forces


def write_csv(df: pd.DataFrame, path: Path, formats: dict[str, str], group: atomic_files) -> None:
    """``df`` as CSV, each column in ``formats`` printed with its %-format, into ``group``."""
    out = df.copy()
    for col, fmt in formats.items():
        out[col] = out[col].map(lambda v, fmt=fmt: fmt % v)
    with group.open(path) as fh:
        out.to_csv(fh, index=False, lineterminator="\n")


# --coupling: the peak of a coupling function, as a fraction of full-scale output
COUPLING_RANGE = (0.0, 0.3)


def with_coupling(sensor: SimulatedSensor, coupling: float) -> SimulatedSensor:
    """``sensor`` with every coupling function's peak at ``coupling`` x full-scale output.

    The shapes stay the sensor's; only ``amplitude`` (peak |phi_ab| over the
    calibrated loads, as a fraction of u_FS,a) changes, off the diagonal.
    """
    lo, hi = COUPLING_RANGE
    if isinstance(coupling, bool) or not isinstance(coupling, numbers.Real) \
            or not lo <= coupling <= hi:
        raise InputError(f"--coupling {coupling!r}: expected the peak coupling as a fraction of "
                         f"full-scale output, from {lo:g} to {hi:g} (e.g. 0.05 for 5 %)")
    n = len(sensor.amplitude)
    amp = tuple(tuple(0.0 if a == b else float(coupling) for b in range(n)) for a in range(n))
    return replace(sensor, amplitude=amp)


# Counts a simulated set may ask for: a calibration is tens of repetitions of tens of
# levels, and --repetitions 1000000000 would run until the memory is gone.
MAX_REPETITIONS, MAX_LEVELS, MAX_SEED = 1000, 10_000, 2**63 - 1


def check_count(value: int, name: str, minimum: int, maximum: int = MAX_SEED) -> None:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) \
            or not minimum <= value <= maximum:
        too_big = isinstance(value, numbers.Integral) and value > maximum
        bound = f"from {minimum} to {maximum}" if too_big else f">= {minimum}"
        raise InputError(f"--{name} {value!r}: expected a whole number {bound}")


@contextlib.contextmanager
def one_set(out: Path, n_reps: int, force: bool):
    """Write a simulated set into ``out`` as one: runs into the same place take turns (an
    exclusive lock named after the place, in the user's cache directory, so nothing is
    made in the user's folders), and with ``force`` the repetition files of an earlier,
    larger set (``calibration/rep7.csv`` beside a new set of six) are removed once the
    new set is in place, so no set is ever read mixed."""
    import fcntl
    import hashlib

    import platformdirs

    locks = Path(platformdirs.user_cache_dir("fsdecouple")) / "locks"
    name = hashlib.sha256(os.fsencode(out.resolve())).hexdigest()[:32]
    try:
        locks.mkdir(parents=True, exist_ok=True)
        fd = os.open(locks / f"simulate-{name}.lock", os.O_RDWR | os.O_CREAT, 0o600)
    except OSError:
        fd = None  # no cache directory: runs into one place are then not kept apart
    try:
        if fd is not None:
            fcntl.flock(fd, fcntl.LOCK_EX)
        yield
        if force and (out / "calibration").is_dir():
            for path in (out / "calibration").iterdir():
                m = re.fullmatch(r"rep(\d+)\.csv", path.name)
                if m and not 1 <= int(m.group(1)) <= n_reps and path.is_file():
                    path.unlink()
    finally:
        if fd is not None:
            os.close(fd)  # and the lock with it


def simulate(
    out_dir: str | Path,
    *,
    seed: int = 0,
    gross_error: GrossError | None = None,
    sensor: SimulatedSensor | None = None,
    force: bool = False,
    layout: str = "paper",
    repetitions: int | None = None,
    levels: int | None = None,
    coupling: float | None = None,
    hysteresis: float | None = None,
) -> list[Path]:
    """Write a simulated calibration data set; all files or, on an error, none.

    ``layout="paper"``: ``OUT_DIR/calibration/rep1.csv .. repN.csv`` on the paper's
    grid (six repetitions unless given), ``OUT_DIR/task_voltages.csv`` and
    ``OUT_DIR/task_forces.csv`` (true forces).  Voltages are written to 0.1 uV.

    ``layout="lab"``: a load cell (:func:`load_cell_sensor` unless given) in a lab's
    spreadsheet (:mod:`fsdecouple.sim.lab`): ``OUT_DIR/calibration.csv`` with
    ``levels`` loads per sweep up to full scale (one repetition unless given) and
    ``OUT_DIR/validation.csv``, the same sensor with its own noise and offsets and
    loads up to 120 % of full scale.  ``gross_error`` moves a calibration point.
    ``coupling`` sets every coupling function's peak to that fraction of its
    output's full scale (:func:`with_coupling`); default: the sensor's own.
    ``hysteresis`` (paper layout): sweeps out and back, and a lag whose way down
    reads that fraction of full-scale output above the way up, in the calibration
    and the task log (:mod:`fsdecouple.sim.hysteresis`).

    A six-axis sensor: :func:`fsdecouple.sim.six_axis.write_six_axis`.
    """
    if layout not in LAYOUTS:
        raise InputError(f"--layout {layout!r}: expected one of {', '.join(LAYOUTS)}")
    check_count(seed, "seed", 0)
    if repetitions is not None:
        check_count(repetitions, "repetitions", 1, MAX_REPETITIONS)
    if levels is not None:
        if layout != "lab":
            raise InputError("--levels: only with --layout lab (the paper layout uses the paper's grid)")
        check_count(levels, "levels", 1, MAX_LEVELS)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: is a file, expected a directory to write into")
    if hysteresis is not None:
        if layout != "paper":
            raise InputError("--hysteresis: only with --layout paper (its sweeps go out and back)")
        check_hysteresis(hysteresis)
    if coupling is not None:
        sensor = with_coupling(sensor or (load_cell_sensor() if layout == "lab"
                                          else SimulatedSensor()), coupling)
    if layout == "lab":
        with one_set(out, 0, force=False):
            return _simulate_lab(out, seed=seed, gross_error=gross_error, sensor=sensor,
                                 force=force, repetitions=repetitions or 1, levels=levels or 4)
    sensor = sensor or SimulatedSensor()
    if hysteresis is not None:
        sensor = replace(sensor, hysteresis=float(hysteresis))
    n_reps = repetitions or 6
    with one_set(out, n_reps, force):
        return _simulate_paper(out, seed=seed, gross_error=gross_error, sensor=sensor, force=force,
                               n_reps=n_reps)


def _simulate_paper(out: Path, *, seed: int, gross_error: GrossError | None,
                    sensor: SimulatedSensor, force: bool, n_reps: int) -> list[Path]:
    for path in (*(out / "calibration" / f"rep{r}.csv" for r in range(1, n_reps + 1)),
                 out / "task_voltages.csv", out / "task_forces.csv"):
        if path.parent.is_dir():  # all or nothing: refuse before the first file is written
            check_output(path, force=force)
    table = simulate_calibration(sensor, repetitions=n_reps, seed=seed)
    if gross_error is not None:
        table = gross_error.apply(table)
    volt_fmt = {c: "%.7f" for c in VOLTAGE_COLUMNS}
    force_fmt = {c: "%.3f" for c in FORCE_COLUMNS}
    written = []
    # every file, and the directories made for them, appear together or not at all
    with atomic_files(force=force) as group:
        for rep, g in table.groupby("repetition"):
            path = out / "calibration" / f"rep{rep}.csv"
            write_csv(g.drop(columns="repetition"), path, {**force_fmt, **volt_fmt}, group)
            written.append(path)
        volts, forces = simulate_task(sensor, seed=seed)
        write_csv(volts, out / "task_voltages.csv", {"t": "%.3f", **volt_fmt}, group)
        write_csv(forces, out / "task_forces.csv", {"t": "%.3f", **force_fmt}, group)
    written += [out / "task_voltages.csv", out / "task_forces.csv"]
    return written


def _simulate_lab(
    out: Path, *, seed: int, gross_error: GrossError | None, sensor: SimulatedSensor | None,
    force: bool, repetitions: int, levels: int,
) -> list[Path]:
    sensor = sensor or load_cell_sensor()
    targets = [out / "calibration.csv", out / "validation.csv"]
    if out.is_dir():  # all or nothing: refuse before the first file is written
        for path in targets:
            check_output(path, force=force)
    # independent streams: the validation set is not the calibration's noise again
    calib_rng, valid_rng = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2))
    calib = simulate_lab_calibration(sensor, calib_rng, levels=levels, repetitions=repetitions)
    if gross_error is not None:
        calib = gross_error.apply(calib)
    valid = simulate_lab_calibration(
        sensor, valid_rng, levels=levels, repetitions=repetitions, reach=VALIDATION_REACH
    )
    with atomic_files(force=force) as group:
        for table, path in zip((calib, valid), targets, strict=True):
            write_lab_csv(table, path, force=force, group=group)
    return targets
