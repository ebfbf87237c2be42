"""A pose calibration of an eight-gauge force/torque sensor (``simulate --rig poses``).

Calibrations outside a lab (issue 32) hang a known mass on the sensor and let a robot
arm turn it: each *pose* holds one orientation while a logger samples the gauges.  The
applied wrench is the mass's weight in the sensor frame and its moment about the
sensor's origin,

    F = m g d,   M = r x F,

d the direction of gravity in the sensor frame and r the mass's centre.  Gravity never
switches off, so no pose is unloaded: the gauges' offsets can only be fitted
(``zero: intercept``).  This simulator draws:

* :data:`POSITIONS` mass positions x :data:`ORIENTATIONS` gravity directions (the
  twelve vertices of an icosahedron, turned by a rotation drawn from the seed);
* eight gauge channels in raw 10-bit ADC counts: an offset near mid-range, a linear mix
  of the six normalised loads (:func:`fsdecouple.sim.rig.gauge_mix`), a quadratic
  nonlinearity of a few % of a channel's span, Gaussian noise, rounded and clipped to
  0 .. 1023;
* :data:`SAMPLES` timestamped samples per pose, of which about :data:`MISREAD` are
  serial misreads (a digit appended: 459 read as 4598);
* three channels whose offsets put them near their upper rail (within 5 % of 1023) on
  about :data:`RAILING` poses in all (fewer where a channel's highest poses spread wider
  than the 5 %).

The truth (loads, noise-free counts) comes back with the rows, so a test can score a
model against it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..files.outputs import atomic_files, check_output
from .rig import gauge_mix
from .simulate import check_count

G = 9.81  # [m/s^2]
MASS = 1.027  # [kg]: a weight of 10.07 N
POSITIONS = np.array([  # the mass's centre in the sensor frame [m]
    [0.0, 0.0, 0.035], [0.02, 0.0, 0.03], [-0.02, 0.005, 0.03], [0.0, 0.02, 0.028],
    [0.005, -0.02, 0.03]])
ORIENTATIONS = 12
SAMPLES = 2000
GAUGES = 8
BITS = 10
SPAN = 260.0  # counts a gauge moves for its largest normalised response
NONLINEAR = 0.03  # largest quadratic term, fraction of SPAN
NOISE = 1.5  # [counts]
MISREAD = 2e-4  # fraction of samples with a digit appended on one channel
RAILING = 15  # poses with one channel near its upper rail
FULL_SCALE = np.array([10.0, 10.0, 10.0, 0.4, 0.4, 0.4])  # normalises the loads [N], [N·m]
LOADS = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")


@dataclass(frozen=True)
class PoseSet:
    """A simulated pose calibration: per pose the applied wrench and the samples."""

    loads: np.ndarray  # (poses, 6) [N, N·m]
    samples: list[np.ndarray]  # per pose, (samples, gauges) integer counts as written
    truth: np.ndarray  # (poses, gauges) noise-free counts of each pose
    railing: np.ndarray  # the channels near their rail


def icosahedron() -> np.ndarray:
    """The twelve unit vertices of an icosahedron, (12, 3): directions in antipodal pairs."""
    phi = (1 + 5 ** 0.5) / 2
    v = [(0, s1, s2 * phi) for s1 in (-1, 1) for s2 in (-1, 1)]
    v = [*v, *[(s1, s2 * phi, 0) for s1 in (-1, 1) for s2 in (-1, 1)],
         *[(s2 * phi, 0, s1) for s1 in (-1, 1) for s2 in (-1, 1)]]
    v = np.array(v, dtype=float)
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def pose_loads(seed: int) -> np.ndarray:
    """The applied wrench of every pose, (POSITIONS x ORIENTATIONS, 6), position-major."""
    rng = np.random.default_rng([32, seed])
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))  # a random rotation of the directions
    d = icosahedron() @ q.T
    out = []
    for r in POSITIONS:
        f = MASS * G * d
        out.append(np.column_stack([f, np.cross(r, f)]))
    return np.concatenate(out)


def simulate_poses(seed: int = 0, samples: int = SAMPLES, gauges: int = GAUGES,
                   dead: int | None = None, drift: float = 0.0, noise_seed: int = 0,
                   coupling: float = 0.0, repeatability: float = 0.0) -> PoseSet:
    """Draw a pose calibration (module docstring); ``dead``: a channel stuck at one value.

    ``repeatability``: each pose's gauges also read off their smooth response by
    repeatability x SPAN N(0, 1), the same for all its samples (creep and hysteresis of a
    printed flexure: the public eight-gauge set's poses sit ~10 % of a span off any
    smooth model while their samples scatter by under a count).  The truth keeps it.

    ``drift``: the same sensor later (in-situ recalibration, fitting/prior.py): each gauge's
    gains scaled by 1 + drift N(0, 1) and its offset moved by drift x SPAN N(0, 1), drawn
    from the seed; ``noise_seed`` draws another calibration's noise and misreads.
    ``coupling``: another drift, every entry of the gauge mix moved by coupling x its RMS
    entry x N(0, 1) (a change of the coupling, not of a gauge's gain).
    """
    rng = np.random.default_rng([320, seed])
    f = pose_loads(seed)
    s = f / FULL_SCALE
    mix = gauge_mix(seed, gauges)  # (gauges, 6), well conditioned
    quad = rng.uniform(-NONLINEAR, NONLINEAR, (gauges, 6))
    top = 2 ** BITS - 1
    offset = rng.uniform(0.35, 0.65, gauges) * top
    if drift:
        moved = np.random.default_rng([321, seed])
        mix = mix * (1.0 + drift * moved.normal(size=(gauges, 1)))
        offset = offset + drift * SPAN * moved.normal(size=gauges)
    if coupling:
        moved = np.random.default_rng([323, seed])
        mix = mix + coupling * np.sqrt((mix ** 2).mean()) * moved.normal(size=mix.shape)
    noise = np.random.default_rng([322, seed, noise_seed]) if noise_seed else rng
    linear = s @ mix.T
    signal = SPAN * (linear + (s ** 2) @ quad.T)
    # RAILING poses near a rail, spread over three channels: each one's offset puts its
    # RAILING / 3 highest poses within 5 % of the upper rail, never clipped at it
    railing = rng.choice(gauges, 3, replace=False)
    for j in railing:
        high = np.sort(signal[:, j])
        n = RAILING // 3
        offset[j] = 0.955 * top - high[-n] + 1.0
        offset[j] = min(offset[j], top - 3 - high[-1])
    truth = offset + signal
    if repeatability:
        truth = truth + repeatability * SPAN * np.random.default_rng([323, seed]).normal(
            size=truth.shape)
    if dead is not None:
        truth[:, dead] = offset[dead]
    out = []
    for p in range(len(f)):
        x = truth[p] + noise.normal(0.0, NOISE, (samples, gauges))
        if dead is not None:
            x[:, dead] = offset[dead]
        x = np.clip(np.rint(x), 0, top).astype(np.int64)
        bad = noise.random(samples) < MISREAD * gauges
        cols = noise.integers(gauges, size=samples)
        x[bad, cols[bad]] = x[bad, cols[bad]] * 10 + noise.integers(0, 10, int(bad.sum()))
        out.append(x)
    return PoseSet(f, out, truth, railing)


def pose_lines(poses: PoseSet, header: bool = True, first: int = 0) -> list[str]:
    """CSV lines of poses ``first ..``: ``timestamp, s0 .. s7, Fx .. Tz``."""
    g = poses.samples[0].shape[1]
    lines = [",".join(["timestamp", *(f"s{j}" for j in range(g)), *LOADS])] if header else []
    for p, (load, x) in enumerate(zip(poses.loads[first:], poses.samples[first:], strict=True),
                                  start=first):
        wrench = ",".join(f"{v:.6f}" for v in load)
        t0 = 60.0 * p
        lines += [f"{t0 + 0.01 * i:.2f}," + ",".join(map(str, row)) + "," + wrench
                  for i, row in enumerate(x.tolist())]
    return lines


def write_poses(out: str | Path, *, seed: int = 0, samples: int = SAMPLES, joined: bool = False,
                dead: int | None = None, force: bool = False) -> list[Path]:
    """Write the poses under ``out``: ``pose01.csv ..`` one per pose, or with ``joined`` one
    ``poses.csv`` with the header once.  Returns the files written."""
    check_count(seed, "seed", 0)
    check_count(samples, "samples", 1, 100_000)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: is a file, expected a directory to write into")
    poses = simulate_poses(seed, samples, dead=dead)
    n = len(poses.loads)
    names = ["poses.csv"] if joined else [f"pose{p + 1:02d}.csv" for p in range(n)]
    paths = [out / name for name in names]
    if out.is_dir():
        for p in paths:
            check_output(p, force=force)
    with atomic_files(force=force) as group:
        group.mkdir(out)
        if joined:
            with group.open(paths[0]) as fh:
                fh.write("\n".join(pose_lines(poses)) + "\n")
        else:
            for p, path in enumerate(paths):
                one = PoseSet(poses.loads[p:p + 1], poses.samples[p:p + 1], poses.truth[p:p + 1],
                              poses.railing)
                with group.open(path) as fh:
                    fh.write("\n".join(pose_lines(one)) + "\n")
    return paths
