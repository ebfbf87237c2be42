"""Interference error gamma (eq. 12) and related figures of merit.

Eq. (12) divides the off-axis forces by the loaded axis's full scale, which needs
one unit for all components.  A six-axis sensor mixes forces [N] and moments
[N·m]; there each off-axis component b is divided by a full scale of its own
unit: the loaded component's, F_a(FS), when b shares a's unit (eq. 12 as
printed), else its own, F_b(FS).  So

    gamma_a = sum_{b != a} max|f_b| / FS_ab,  FS_ab = F_a(FS) if unit_b = unit_a else F_b(FS),

is dimensionless, and for a sensor whose components share one unit (every
3-axis force sensor) it *is* eq. (12), whatever the full scales.
"""

from __future__ import annotations

import math

import numpy as np

from ..axes import DEFAULT, Layout
from ..errors import InputError


def interference_error(forces: np.ndarray, axis: int, full_scale, units=None) -> float:
    """gamma of eq. (12) for single-axis loads along ``axis``.

    gamma_x = (max |f_y(m)| + max |f_z(m)|) / f_x(FS): the largest decoupled forces
    on the two unloaded axes, as a fraction of the loaded axis's full scale.

    Parameters
    ----------
    forces : ndarray, shape (n, N)
        Measured (decoupled) forces of the ``axis`` sweep points [N].
    axis : int
        0, 1, 2 for the loaded axis x, y, z (the component's index).
    full_scale : float or sequence of float
        f_(FS) of the loaded axis [N] (eq. 12 as printed), or the full scale of
        every component, for the mixed-unit form of the module docstring.
    units : sequence of str, optional
        Each component's load unit; None: one unit for all (eq. 12).
    """
    fs = np.atleast_1d(np.asarray(full_scale, dtype=float))
    n = forces.shape[-1] if np.ndim(forces) == 2 else (fs.size if fs.size > 1 else 3)
    forces = np.asarray(forces, dtype=float).reshape(-1, n)
    others = [a for a in range(n) if a != axis]
    if fs.size == 1:
        return float(sum(np.abs(forces[:, o]).max() for o in others) / fs[0])
    own = [o for o in others if units is not None and units[o] != units[axis]]
    shared = [o for o in others if o not in own]  # eq. (12) as printed, summed as it is
    return float(sum(np.abs(forces[:, o]).max() for o in shared) / fs[axis]
                 + sum(np.abs(forces[:, o]).max() / fs[o] for o in own))


def interference_errors(points, forces: np.ndarray, full_scale, layout: Layout = DEFAULT,
                        units=None) -> dict[str, float]:
    """gamma for each loaded axis of a calibration set (all its repetitions pooled).

    ``units``: each component's load unit (mixed units: module docstring); None: one unit.
    """
    axis = points["axis"].to_numpy()
    # the off-axis loads a row really carries (a lever arm's force) are no interference:
    # gamma counts decoupled minus applied, which on single-axis rows is eq. (12) itself
    errors = np.asarray(forces, dtype=float)
    if set(layout.loads) <= set(points.columns):
        errors = errors - points[list(layout.loads)].to_numpy(dtype=float)
    return {
        a: interference_error(errors[axis == a], i, full_scale, units)
        for i, a in enumerate(layout.labels)
        if (axis == a).any()
    }


def pct(fraction: float | None, digits: int = 2) -> str:
    """A fraction of full scale as percent text, ``0.0123`` -> ``1.23 %``; ``–`` for none."""
    return "–" if fraction is None else f"{100.0 * fraction:.{digits}f} %"


def check_max_gamma(max_gamma: float | None) -> None:
    """A ``--max-gamma`` gate must be a finite fraction of full scale above 0 (NaN never fails)
    and below 1: a gate of 100 % F.S. or more is a percentage written for a fraction (1
    meant as 1 %), which held-out errors of a working model never reach."""
    if max_gamma is not None and not (math.isfinite(max_gamma) and max_gamma > 0):
        raise InputError(f"gate on gamma {max_gamma}: expected a fraction greater than 0, e.g. 0.016",
                         argument="max_gamma")
    if max_gamma is not None and max_gamma >= 1:
        raise InputError(f"gate on gamma {max_gamma:g}: a fraction of full scale, so {max_gamma:g} "
                         f"is {100 * max_gamma:g} %, a gate no working model comes near; for "
                         f"{max_gamma:g} % write {max_gamma / 100:g}", argument="max_gamma")
