"""Pose logs (issue 22): many timestamped samples of one static load, averaged per load.

A rig that holds each load while a logger samples the sensor writes a *pose log*: a
timestamp column and runs of consecutive rows with the same applied loads.  The paper's
fit wants one reading per load (Section 3: a calibration point is a load and its
outputs), and an SVR fitted to hundreds of samples of each load would follow their
noise.  So, in a file with a timestamp column, each run of two or more consecutive rows
with equal applied loads (and equal repetition and axis cells, where mapped) becomes one
calibration point: the mean of its outputs, named by the run's first line.  The scatter
of the samples about their pose's mean is the noise: pooled over every pose,

    s_j^2 = sum_p sum_i (u_ij - mean_p u_j)^2 / sum_p (n_p - 1)

per output j, and an average of n_p samples has sigma_j^2 = s_j^2 mean_p(1 / n_p).  That
sigma is what the joint fit of rig rows takes as its epsilon-tube
(:func:`fsdecouple.fitting.joint.joint_svr`) in place of its pilot fit's residual scatter.
Files without a timestamp column, and rows whose loads differ from their neighbours', are
read as they are.
"""

from __future__ import annotations

import numpy as np

from .columns import _parse_name

TIMESTAMP_NAMES = {"time", "timestamp", "datetime", "date", "t", "timesec", "elapsed",
                   "elapsedtime"}


def timestamp_column(header) -> str | None:
    """The first header name that names a timestamp (units and separators ignored)."""
    return next((h for h in header if _parse_name(str(h))[0] in TIMESTAMP_NAMES), None)


def average_poses(frame, keys: list[str], outputs: list[str]):
    """``(frame, ss, dof, runs)``: runs of equal ``keys`` in consecutive rows averaged.

    ``frame`` (pandas, file order) holds ``row``, ``keys`` and ``outputs``; each run of two
    or more rows keeps its first row with the mean outputs.  ``ss`` (per output) and
    ``dof``: the within-run sums of squares and degrees of freedom; ``runs``: (first line,
    last line, samples) per averaged run, and ``inverse``: sum over the runs of 1 / n.
    """
    n = len(frame)
    if n < 2:
        return frame, np.zeros(len(outputs)), 0, [], 0.0
    k = frame[keys].to_numpy()
    same = np.ones(n - 1, dtype=bool)
    for c in range(k.shape[1]):
        same &= k[1:, c] == k[:-1, c]
    start = np.concatenate([[True], ~same])
    run = np.cumsum(start) - 1
    counts = np.bincount(run)
    if counts.max() < 2:
        return frame, np.zeros(len(outputs)), 0, [], 0.0
    u = frame[outputs].to_numpy(dtype=float)
    sums = np.zeros((counts.size, u.shape[1]))
    np.add.at(sums, run, u)
    means = sums / counts[:, None]
    ss = ((u - means[run]) ** 2).sum(axis=0)
    dof = int((counts - 1).sum())
    rows = frame["row"].to_numpy()
    first = np.flatnonzero(start)
    last = np.append(first[1:], n) - 1
    runs = [(int(rows[a]), int(rows[b]), int(c))
            for a, b, c in zip(first, last, counts, strict=True) if c > 1]
    out = frame.iloc[first].copy()
    out[outputs] = means
    return out.reset_index(drop=True), ss, dof, runs, float((1.0 / counts[counts > 1]).sum())


def pose_note(path, runs, samples: int) -> str:
    """One line naming the poses averaged in a file."""
    shown = ", ".join(f"{a}-{b}" for a, b, _ in runs[:3]) + (", ..." if len(runs) > 3 else "")
    return (f"{path}: {samples} timestamped samples of {len(runs)} static loads (lines {shown}) "
            "averaged per load; their scatter is the noise sigma (docs/rigs.md)")
