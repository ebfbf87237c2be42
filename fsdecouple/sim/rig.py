"""A lever-arm force/torque rig's calibration file (``simulate --rig lever-arm``).

A real six-axis rig applies a moment as a force on a lever arm, so every moment
row loads a force too (issue 22): the Mx rows load Fy, the My and Mz rows load Fx.
The sensor's readings are already nearly calibrated (columns ``Fx .. Mz`` in N
and N·m) with a few % linear cross-talk and a quadratic/cubic coupling
nonlinearity, plus a milder nonlinearity of each component in its own load, the
kind a factory matrix leaves behind.  The applied loads are ``known_Fx ..
Known_Mz`` (mixed case), six sweeps of :data:`LEVELS` levels, each after one zero
row, a timestamp column and trailing empty rows.  ``gauges = 8`` writes eight
strain-gauge channels ``g1 .. g8`` instead (M > N): a fixed 8 x 6 mix of the readings.

``simulate --rig quadratic`` is the same rig with the nonlinearity of issue 22's public
rig file: each reading bends with the square of its own load (1-3 % F.S. at full
scale) and of the other loads (up to 1.5 %), with 0.1 % F.S. noise, so a least-squares
fit with squared terms has about 0.6 x the matrix's held-out error, as it had there.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..files.outputs import atomic_files, check_output
from .simulate import MAX_LEVELS, check_count

COMPONENTS = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")
FULL_SCALE = np.array([100.0, 100.0, 200.0, 5.0, 5.0, 5.0])  # [N], [N·m]
LEVELS = 9  # loads per sweep after its zero row: FS/9 .. FS
ARM = 0.1  # lever arm [m]: Mx = -ARM * Fy, My = ARM * Fx, Mz = ARM * Fx
CROSS_TALK = 0.03  # largest linear cross-talk, fraction of full scale
COUPLING = 0.01  # largest quadratic + cubic coupling term, fraction of full scale
SELF = 0.002  # largest nonlinearity of a component in its own load, fraction of F.S.
NOISE = 2e-4  # reading noise, fraction of full scale
# ``quadratic``: own-load square 1-3 % F.S. (either sign), other loads' squares up to
# 1.5 %, cubes up to 0.3 %, noise 0.1 % F.S.
QUADRATIC = {"own": 0.03, "cross": 0.015, "cubic": 0.003, "noise": 1e-3}
RIGS = ("lever-arm", "quadratic")  # and "poses" (sim/poses.py), written by its own writer
MAX_GAUGES = 64  # output channels of a rig: --gauges 100000000 would fill the memory
# which force the lever arm loads with each moment, and its sign per N·m
LEVER = {3: (1, -1.0 / ARM), 4: (0, 1.0 / ARM), 5: (0, 1.0 / ARM)}


def rig_sensor(seed: int, kind: str = "lever-arm") -> dict[str, np.ndarray]:
    """The sensor's true coefficients, normalised: s = f / FS in, r / FS out."""
    rng = np.random.default_rng(seed)
    n = len(COMPONENTS)
    off = ~np.eye(n, dtype=bool)
    linear = np.eye(n) + off * rng.uniform(-CROSS_TALK, CROSS_TALK, (n, n))
    if kind == "quadratic":
        q = QUADRATIC
        quad = off * rng.uniform(-q["cross"], q["cross"], (n, n))
        cubic = off * rng.uniform(-q["cubic"], q["cubic"], (n, n))
        quad[~off] = rng.choice([-1.0, 1.0], n) * rng.uniform(q["own"] / 3, q["own"], n)
        cubic[~off] = rng.uniform(-q["cubic"], q["cubic"], n)
        return {"linear": linear, "quad": quad, "cubic": cubic}
    quad = off * rng.uniform(-COUPLING, COUPLING, (n, n))
    cubic = off * rng.uniform(-COUPLING, COUPLING, (n, n))
    quad[~off] = rng.uniform(-SELF, SELF, n)
    cubic[~off] = rng.uniform(-SELF, SELF, n)
    return {"linear": linear, "quad": quad, "cubic": cubic}


def readings(s: np.ndarray, sensor: dict[str, np.ndarray]) -> np.ndarray:
    """Normalised readings of normalised loads ``s`` (n, 6): linear plus, per source b,
    a quadratic and cubic term in s_b (coupling functions of eq. 3 that are not linear)."""
    return s @ sensor["linear"].T + (s ** 2) @ sensor["quad"].T + (s ** 3) @ sensor["cubic"].T


def gauge_mix(seed: int, gauges: int) -> np.ndarray:
    """A fixed, well-conditioned (gauges, 6) mix of the readings into gauge channels."""
    rng = np.random.default_rng(seed + 1000)
    q, _ = np.linalg.qr(rng.normal(size=(gauges, len(COMPONENTS))))
    return q * rng.uniform(0.5, 1.5, len(COMPONENTS))


def rig_rows(seed: int, levels: int = LEVELS, kind: str = "lever-arm"
             ) -> tuple[np.ndarray, np.ndarray]:
    """(applied loads [N, N·m], outputs) of the six sweeps, each after one zero row."""
    sensor = rig_sensor(seed, kind)
    noise = QUADRATIC["noise"] if kind == "quadratic" else NOISE
    rng = np.random.default_rng(seed + 1)
    loads = []
    for a in range(len(COMPONENTS)):
        loads.append(np.zeros(len(COMPONENTS)))
        for level in np.arange(1, levels + 1) / levels:
            row = np.zeros(len(COMPONENTS))
            row[a] = level * FULL_SCALE[a]
            if a in LEVER:  # the moment comes from a force on the lever arm
                b, per = LEVER[a]
                row[b] = per * row[a]
            loads.append(row)
    f = np.array(loads)
    r = readings(f / FULL_SCALE, sensor)
    r = (r + rng.normal(0.0, noise, r.shape)) * FULL_SCALE
    return f, r


def write_rig(out: str | Path, *, seed: int = 0, gauges: int = 6, levels: int = LEVELS,
              force: bool = False, kind: str = "lever-arm") -> list[Path]:
    """Write ``calibration.csv`` of a lever-arm rig under ``out``; returns the file written.

    ``kind``: ``lever-arm`` or ``quadratic`` (module docstring).
    """
    if kind not in RIGS:
        raise InputError(f"--rig {kind!r}: expected {', '.join(RIGS)} or poses")
    check_count(seed, "seed", 0)
    if isinstance(gauges, int) and gauges < len(COMPONENTS):
        raise InputError(f"--gauges {gauges}: a six-axis rig needs at least 6 output channels")
    check_count(gauges, "gauges", len(COMPONENTS), MAX_GAUGES)
    if isinstance(levels, int) and levels < 2:
        raise InputError(f"--levels {levels}: a sweep needs at least 2 load levels")
    check_count(levels, "levels", 2, MAX_LEVELS)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: is a file, expected a directory to write into")
    path = out / "calibration.csv"
    if out.is_dir():
        check_output(path, force=force)
    f, r = rig_rows(seed, levels, kind)
    if gauges == len(COMPONENTS):
        names, values = list(COMPONENTS), r
    else:
        names = [f"g{i + 1}" for i in range(gauges)]
        values = (r / FULL_SCALE) @ gauge_mix(seed, gauges).T
    loads = [("known_" if c[0] == "F" else "Known_") + c for c in COMPONENTS]
    lines = [",".join(["timestamp", *names, *loads])]
    for i, (fi, ri) in enumerate(zip(f, values, strict=True)):
        stamp = f"2026-01-01T00:{i // 60:02d}:{i % 60:02d}"
        lines.append(",".join([stamp, *(f"{v:.6f}" for v in ri), *(f"{v:.10g}" for v in fi)]))
    lines += ["," * (len(names) + len(loads))] * 2  # trailing empty rows, as spreadsheets leave
    with atomic_files(force=force) as group:  # a directory it made is removed on failure
        group.mkdir(out)
        with group.open(path) as fh:
            fh.write("\n".join(lines) + "\n")
    return [path]
