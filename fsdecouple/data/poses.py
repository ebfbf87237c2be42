"""Pose logs (issue 22): many timestamped samples of one static load, averaged per load.

A rig that holds each load while a logger samples the sensor writes a *pose log*: a
timestamp column and runs of consecutive rows with the same applied loads.  The paper's
fit wants one reading per load (Section 3: a calibration point is a load and its
outputs), and an SVR fitted to hundreds of samples of each load would follow their
noise.  So, in a file with a timestamp column whose runs of equal loads mostly hold
several rows (:func:`is_pose_log`), each run of two or more consecutive rows with equal applied
loads (and equal repetition and axis cells, where mapped) becomes one
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

from .guesses import parse_name

TIMESTAMP_NAMES = {"time", "timestamp", "datetime", "date", "t", "timesec", "elapsed",
                   "elapsedtime"}


def timestamp_column(header) -> str | None:
    """The first header name that names a timestamp (units and separators ignored)."""
    return next((h for h in header if parse_name(str(h))[0] in TIMESTAMP_NAMES), None)


def is_pose_log(counts: np.ndarray) -> bool:
    """Runs of equal loads of these lengths (``counts``, file order) make a pose log: at
    least half the runs hold two rows or more.  A sweep whose zero row ends one
    component's sweep and starts the next, or that holds its peak twice at a turn,
    repeats a load once in a while, between runs of one row; those rows are calibration
    points of their own, not samples."""
    return 2 * int((counts > 1).sum()) >= len(counts)


def average_poses(frame: dict, keys: list[str], outputs: list[str]):
    """``(frame, ss, dof, runs)``: runs of equal ``keys`` in consecutive rows averaged.

    ``frame`` (column name to array, file order) holds ``row``, ``keys`` and ``outputs``;
    each run of two or more rows keeps its first row with the mean outputs.  ``ss`` (per output) and
    ``dof``: the within-run sums of squares and degrees of freedom; ``runs``: (first line,
    last line, samples) per averaged run, and ``inverse``: sum over the runs of 1 / n.
    """
    n = len(frame["row"])
    if n < 2:
        return frame, np.zeros(len(outputs)), 0, [], 0.0
    same = np.ones(n - 1, dtype=bool)
    for key in keys:
        k = frame[key]
        same &= k[1:] == k[:-1]
    start = np.concatenate([[True], ~same])
    run = np.cumsum(start) - 1
    counts = np.bincount(run)
    if counts.max() < 2 or not is_pose_log(counts):
        return frame, np.zeros(len(outputs)), 0, [], 0.0
    # column-major, as a DataFrame's: a sum's rounding depends on the order it runs in
    u = np.vstack([frame[c] for c in outputs]).astype(float).T
    keep = robust_keep(u, run, counts)
    kept = np.bincount(run[keep], minlength=counts.size)
    sums = np.zeros((counts.size, u.shape[1]))
    np.add.at(sums, run[keep], u[keep])
    means = sums / kept[:, None]
    ss = ((u[keep] - means[run[keep]]) ** 2).sum(axis=0)
    dof = int((kept - 1).sum())
    rows = frame["row"]
    first = np.flatnonzero(start)
    last = np.append(first[1:], n) - 1
    runs = [(int(rows[a]), int(rows[b]), int(c), int(c - k))
            for a, b, c, k in zip(first, last, counts, kept, strict=True) if c > 1]
    out = {c: v[first] for c, v in frame.items()}
    out.update({c: means[:, j] for j, c in enumerate(outputs)})
    return out, ss, dof, runs, float((1.0 / kept[counts > 1]).sum())


# A sample further than this many robust sigmas (1.4826 MAD, at least the readings' quantum)
# from its pose's median on any output is rejected: a serial misread (459 read as 4598) is
# hundreds of sigmas out, and Gaussian noise passes 6 sigma once in 5e8 samples.
REJECT = 6.0


def robust_keep(u: np.ndarray, run: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Which samples (rows of ``u``) to average: those within REJECT robust sigmas of their
    run's median on every output.  The robust sigma of an output is 1.4826 x the median
    absolute deviation, the larger of its run's and of all runs' pooled (a MAD of a dozen
    samples can be a third of sigma by chance), and at least the readings' quantum (a MAD
    of 0 counts must not reject a step of 1).  Runs of fewer than 3 samples keep every
    sample."""
    keep = np.ones(len(u), dtype=bool)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    big = [(s, c) for s, c in zip(starts, counts, strict=True) if c >= 3]
    if not big:
        return keep
    dev = np.zeros_like(u)
    for s, c in big:
        dev[s:s + c] = np.abs(u[s:s + c] - np.median(u[s:s + c], axis=0))
    inside = np.concatenate([np.arange(s, s + c) for s, c in big])
    pooled = 1.4826 * np.median(dev[inside], axis=0)
    for s, c in big:
        x = u[s:s + c]
        mad = 1.4826 * np.median(dev[s:s + c], axis=0)
        steps = np.diff(np.sort(x, axis=0), axis=0)
        quantum = np.where(steps > 0, steps, np.inf).min(axis=0, initial=np.inf)
        quantum = np.where(np.isfinite(quantum), quantum, 0.0)
        scale = np.maximum(np.maximum(mad, pooled), quantum)
        keep[s:s + c] = (dev[s:s + c] <= REJECT * scale).all(axis=1)
    return keep


def pose_note(path, runs, samples: int, files: int = 0) -> str:
    """One line naming the poses averaged in a file (or in ``files`` pose files), and the
    samples rejected per pose.  ``runs``: (first line, last line, samples, rejected); in a
    pose directory (first line as "FILE, lines A-B", "")."""
    def span(a, b):
        return f"{a}-{b}" if b != "" else a
    shown = ", ".join(span(a, b) for a, b, *_ in runs[:3]) + (", ..." if len(runs) > 3 else "")
    rejected = [(a, b, r) for a, b, _, r in runs if r]
    told = "; ".join(f"{'lines ' if b != '' else ''}{span(a, b)}: {r}" for a, b, r in rejected[:8]) + \
        ("; ..." if len(rejected) > 8 else "")
    if files:
        return (f"{path}: {files} pose files, one calibration set: {samples} timestamped samples "
                f"averaged per pose ({shown})"
                + (f"; samples rejected as beyond {REJECT:g} robust sigmas of their pose's median "
                   f"(misreads), {sum(r for *_, r in rejected)} in {len(rejected)} poses ({told})"
                   if rejected else "; no sample rejected")
                + "; their scatter is the noise sigma (docs/rigs.md)")
    dropped = (f"; samples rejected as beyond {REJECT:g} robust sigmas of their pose's median "
               f"(misreads), {sum(r for *_, r in rejected)} in {len(rejected)} poses ({told})"
               if rejected else "; no sample rejected")
    return (f"{path}: {samples} timestamped samples of {len(runs)} static loads (lines {shown}) "
            f"averaged per load{dropped}; their scatter is the noise sigma (docs/rigs.md)")
