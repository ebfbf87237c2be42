"""Interference error gamma (eq. 12) and related figures of merit."""

from __future__ import annotations

import math

import numpy as np

from .axes import AXES
from .errors import InputError


def interference_error(forces: np.ndarray, axis: int, full_scale: float) -> float:
    """gamma of eq. (12) for single-axis loads along ``axis``.

    gamma_x = (max |f_y(m)| + max |f_z(m)|) / f_x(FS): the largest decoupled forces
    on the two unloaded axes, as a fraction of the loaded axis's full scale.

    Parameters
    ----------
    forces : ndarray, shape (n, 3)
        Measured (decoupled) forces of the ``axis`` sweep points [N].
    axis : int
        0, 1, 2 for the loaded axis x, y, z.
    full_scale : float
        f_(FS) of the loaded axis [N].
    """
    forces = np.asarray(forces, dtype=float).reshape(-1, 3)
    others = [a for a in range(3) if a != axis]
    return float(sum(np.abs(forces[:, o]).max() for o in others) / full_scale)


def interference_errors(points, forces: np.ndarray, full_scale) -> dict[str, float]:
    """gamma for each loaded axis of a calibration set (all its repetitions pooled)."""
    axis = points["axis"].to_numpy()
    return {
        a: interference_error(forces[axis == a], i, full_scale[i])
        for i, a in enumerate(AXES)
        if (axis == a).any()
    }


def pct(fraction: float | None, digits: int = 2) -> str:
    """A fraction of full scale as percent text, ``0.0123`` -> ``1.23 %``; ``–`` for none."""
    return "–" if fraction is None else f"{100.0 * fraction:.{digits}f} %"


def check_max_gamma(max_gamma: float | None) -> None:
    """A ``--max-gamma`` gate must be a finite fraction of full scale above 0 (NaN never fails)."""
    if max_gamma is not None and not (math.isfinite(max_gamma) and max_gamma > 0):
        raise InputError(f"--max-gamma {max_gamma}: expected a fraction greater than 0, e.g. 0.016")
