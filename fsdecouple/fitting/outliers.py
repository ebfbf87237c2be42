"""Gross errors (Section 4.4) in a calibration set: leave-one-out residuals, flagged robustly.

For every loaded axis a, the prime outputs of the a sweeps are fitted by least
squares through the origin, u_aa = k_aa f_a (eq. 2; the data are zero-corrected and
assumption 1 of Section 2.1 makes the relation linear).  The leave-one-out
residual of point i is e_i / (1 - h_ii) (h: the fit's hat matrix), i.e. how far the
point lies from the fit of all the others, without refitting; divided by k_aa it
is a load error in the data's load unit, and a fraction of full scale.

A point is flagged when its size exceeds both FLOOR (a fraction of full scale, so
that noise is never flagged) and MAD_FACTOR robust standard deviations (1.4826 x
the median absolute deviation of all axes' leave-one-out residuals together: one
sweep of a single repetition has too few points for a spread of its own).  The
largest is flagged and left out, and the axis checked again, so one gross error
does not drag its neighbours' residuals over the limit.  The coupling outputs are
not checked: their shape is the unknown the SVRs learn, so a residual there cannot
tell a gross error from coupling.  A rig whose rows load several components is checked
over all its rows at once, each prime output fitted on every load and its square
(:func:`joint_gross_errors`, issue 32).  Nothing is dropped: ``fit --exclude FILE:LINE``
drops a point the technician has checked.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..axes import DEFAULT, Layout

FLOOR = 0.005  # 0.5 % of full scale: well above sensor noise, below a typical gross error
MAD_FACTOR = 5.0  # robust standard deviations
MAD_TO_SIGMA = 1.4826  # a normal distribution's sigma per median absolute deviation


@dataclass(frozen=True)
class Outlier:
    """One flagged calibration point."""

    file: str
    row: int
    axis: str  # loaded axis of its sweep
    output: str  # the output channel whose residual is an outlier
    size: float  # load error [load unit] on that channel
    fraction: float  # of that channel's full scale

    joint: bool = False  # checked against every other row (rows loading several components)

    def message(self, load_unit: str) -> str:
        other = ("every other row (all loads, each one's bend included)" if self.joint
                 else f"the other {self.axis}-sweep points")
        return (f"{self.file}, row {self.row}: possible gross error: {self.output} is "
                f"{self.size:+.4g} {load_unit} ({100 * self.fraction:+.2f} % F.S.) away from the "
                f"leave-one-out fit of {other}; check it, and drop it "
                f"by excluding '{self.file}:{self.row}' if it is wrong")


def loo_residuals(x: np.ndarray, y: np.ndarray, degree: int) -> np.ndarray:
    """Leave-one-out residuals of a least-squares polynomial through the origin.

    Returns NaN where a point cannot be left out (h_ii = 1: too few points).
    """
    design = np.column_stack([x ** p for p in range(1, degree + 1)])
    q, _ = np.linalg.qr(design)
    h = np.einsum("ij,ij->i", q, q)
    fitted = q @ (q.T @ y)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = (y - fitted) / (1.0 - h)
    out[h > 1.0 - 1e-9] = np.nan
    return out


def joint_loo(s: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Leave-one-out residuals of y fitted by least squares on every load and its square.

    ``s``: loads as fractions of full scale (n, N).  A rig's rows load several components
    (a lever arm's force beside its moment), and its outputs bend with their loads' squares
    (issue 22's public rig): a straight line of one sweep blames the sweep's far end for
    the bend, and a row's lever-arm force for coupling.  The hat matrix comes from the
    design's SVD, so loads that move together (a weight's |F| is constant) cost no rank.
    """
    design = np.column_stack([s, s ** 2])
    u, sv, _ = np.linalg.svd(design, full_matrices=False)
    q = u[:, :int((sv > sv[0] * 1e-10).sum())] if sv.size and sv[0] > 0 else u[:, :0]
    h = np.einsum("ij,ij->i", q, q)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = (y - q @ (q.T @ y)) / (1.0 - h)
    out[h > 1.0 - 1e-9] = np.nan
    return out


def _limit(fractions: np.ndarray) -> float | None:
    """The flagging limit over the leave-one-out residuals ``fractions`` [fraction of F.S.]:
    ``MAD_FACTOR`` robust sigmas (the MAD), never below ``FLOOR``; None without a finite one."""
    fractions = fractions[np.isfinite(fractions)]
    if fractions.size == 0:
        return None
    mad = MAD_TO_SIGMA * np.median(np.abs(fractions - np.median(fractions)))
    return max(FLOOR, MAD_FACTOR * mad)


def joint_gross_errors(points, k: np.ndarray, full_scale, layout: Layout) -> list[Outlier]:
    """Rows loading several components: each prime output's leave-one-out residual over every
    row, in load space (divided by k_aa: eq. 2), flagged as the per-sweep check flags them."""
    fs = np.asarray(full_scale, dtype=float)
    s = points[list(layout.loads)].to_numpy(dtype=float) / fs
    u = points[list(layout.outputs)].to_numpy(dtype=float)
    first = np.column_stack([joint_loo(s, u[:, a]) / abs(k[a]) / fs[a] for a in range(layout.n)])
    limit = _limit(first)
    if limit is None:
        return []
    found = []
    for a in range(layout.n):
        keep = np.ones(len(s), dtype=bool)
        while keep.sum() > 2 * s.shape[1] + 2:
            idx = np.flatnonzero(keep)
            r = joint_loo(s[idx], u[idx, a]) / abs(k[a])
            frac = np.where(np.isfinite(r), np.abs(r) / fs[a], 0.0)
            worst = int(np.argmax(frac))
            if frac[worst] <= limit:
                break
            i = idx[worst]
            found.append(Outlier(str(points["file"].iat[i]), int(points["row"].iat[i]),
                                 str(points["axis"].iat[i]), layout.outputs[a], float(r[worst]),
                                 float(r[worst] / fs[a]), joint=True))
            keep[i] = False
    return sorted(found, key=lambda o: -abs(o.fraction))


def gross_errors(points, k: np.ndarray, full_scale, layout: Layout = DEFAULT) -> list[Outlier]:
    """Every point whose leave-one-out residual on its prime output is an outlier, largest first.

    Rows loading several components are checked jointly (:func:`joint_gross_errors`)."""
    forces = points[list(layout.loads)].to_numpy()
    if ((forces != 0.0).sum(axis=1) > 1).any():
        return joint_gross_errors(points, k, full_scale, layout)
    sweeps = []
    for a, axis in enumerate(layout.labels):
        s = points[points["axis"] == axis]
        f = s[layout.loads[a]].to_numpy(dtype=float)
        u = s[layout.outputs[a]].to_numpy(dtype=float)
        if f.size > 2:
            sweeps.append((a, axis, s, f, u))
    fractions = [loo_residuals(f, u, 1) / abs(k[a]) / full_scale[a] for a, _, _, f, u in sweeps]
    limit = _limit(np.concatenate(fractions) if fractions else np.empty(0))
    if limit is None:
        return []
    found = []
    for a, axis, s, f, u in sweeps:
        keep = np.ones(f.size, dtype=bool)
        while keep.sum() > 2:
            idx = np.flatnonzero(keep)
            r = loo_residuals(f[idx], u[idx], 1) / abs(k[a])
            frac = np.where(np.isfinite(r), np.abs(r) / full_scale[a], 0.0)
            worst = int(np.argmax(frac))
            if frac[worst] <= limit:
                break
            i = idx[worst]
            found.append(Outlier(str(s["file"].iat[i]), int(s["row"].iat[i]), axis,
                                 layout.outputs[a], float(r[worst]),
                                 float(r[worst] / full_scale[a])))
            keep[i] = False
    return sorted(found, key=lambda o: -abs(o.fraction))
