"""The calibration's noise, and libsvm's stopping tolerance measured against it.

libsvm stops when its KKT violations fall below ``-e`` (Table 2: 1e-3), in the
units of the SVR's target.  In volts (``scaling: none``) that is the paper's own
setting.  In normalised units (``scaling: full_scale``, automatic for outputs in mV,
counts or mV/V) it is 1e-3 F.S.: on six-axis sensors 2-4x the noise, the solver
stops short of eq. (8)'s optimum and each chi misses the true one by about half
the noise; an output sums five of them (README, "Against a straightforward
reference": 2.6x the floor, against 1.5x when solved to the noise).  So a sensor
with ``components:`` fitted in normalised units is solved to at most
NOISE_FRACTION sigma (and at least MIN_TOLERANCE F.S., for noise-free data).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ..config import Settings
    from ..data.calibration import CalibrationSet

NOISE_FRACTION = 0.5  # of sigma: at 1.4 sigma the chi were no better than at 1e-3
MIN_TOLERANCE = 1e-5  # [F.S.], as tune.TUNE_TOLERANCE


def noise(calib: CalibrationSet, settings: Settings, k: np.ndarray | None = None) -> float | None:
    """sigma: the scatter of repeated loads, as a fraction of full-scale output.

    Points of the same sweep axis and load in different repetitions are repeats; the
    pooled standard deviation of every output about its repeats' mean, divided by
    the output's full-scale output |k| F_FS (k from eq. 2), is pooled over the
    outputs (root mean square).  None without two repetitions of any loaded point.
    ``k``: the slopes if already fitted (eq. 2), else fitted here.
    """
    from .linear import fit_omega

    pts, layout = calib.points, settings.layout
    k = fit_omega(pts, layout).k if k is None else k
    forces = pts[list(layout.loads)].to_numpy()
    loaded = (forces != 0.0).any(axis=1)
    u_fs = np.abs(k) * np.asarray(settings.full_scale)
    u = pts[list(layout.outputs)].to_numpy() / u_fs
    keys = [tuple(r) for r in np.column_stack([pts["axis"].map(layout.labels.index), forces])]
    groups: dict[tuple, list[int]] = {}
    for i, key in enumerate(keys):
        if loaded[i]:
            groups.setdefault(key, []).append(i)
    ss, dof = 0.0, 0
    for idx in groups.values():
        if len(idx) > 1:
            g = u[idx]
            ss += float(((g - g.mean(axis=0)) ** 2).sum())
            dof += (len(idx) - 1) * g.shape[1]
    return math.sqrt(ss / dof) if dof else None


def solved_to_the_noise(calib: CalibrationSet, settings: Settings,
                        k: np.ndarray | None = None) -> Settings:
    """``settings`` with libsvm's tolerance at most NOISE_FRACTION sigma [F.S.].

    Only for a sensor with ``components:`` fitted with ``scaling: full_scale``; three
    axes and volts keep the configured tolerance.  Without repeated loads (one
    repetition) sigma is unknown and the tolerance stays as configured.
    """
    if settings.components is None or settings.scaling != "full_scale":
        return settings
    sigma = noise(calib, settings, k)
    if sigma is None or not math.isfinite(sigma):
        return settings
    tol = max(MIN_TOLERANCE, min(settings.svr.tolerance, NOISE_FRACTION * sigma))
    return replace(settings, svr=replace(settings.svr, tolerance=float(tol)))
