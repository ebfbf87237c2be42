"""Hysteresis for the simulated sensor, and the up-and-down sweeps that show it.

A real sensor's elastic body lags its load: on the way up its outputs read a
little low, on the way down a little high.  The simulator models the lag per
component as a Duhem-type state z_b [load unit] that relaxes towards -r_b while
the load rises and towards +r_b while it falls,

    z <- t + (z - t) exp(-|df| / lambda_b),   t = -sign(df) r_b,

and the sensor's outputs are those of the lagged loads f + z (eq. 1-3 at
f + z: the prime output and every coupling error element follow the body's
deflection).  r_b = fraction / 2 x F_FS,b, so on a long monotone stretch the way
down reads ``fraction`` x the full-scale output above the way up;
lambda_b = WIDTH x F_FS,b.  On a full up-and-down loop the branches meet at the
turning points and lie furthest apart mid-range (a ±F_FS loop: 0.96 x
``fraction`` at zero load).  The state starts at 0 (no load history) and
depends on the path, so a combined-load log is lagged sample by sample.

No decoupler of the paper's static model (eq. 1) can represent the lag: it is
part of the floor (the error left with the true coupling functions).
"""

from __future__ import annotations

import numbers

import numpy as np

from ..errors import InputError

WIDTH = 0.25  # lambda_b / F_FS,b: a load change of a quarter full scale settles 63 % of the lag
HYSTERESIS_RANGE = (0.0, 0.05)  # --hysteresis: down minus up, fraction of full-scale output


def check_hysteresis(fraction: float) -> None:
    lo, hi = HYSTERESIS_RANGE
    if isinstance(fraction, bool) or not isinstance(fraction, numbers.Real) \
            or not lo <= fraction <= hi:
        raise InputError(f"--hysteresis {fraction!r}: expected the difference between the way "
                         f"down and the way up as a fraction of full-scale output, from {lo:g} "
                         f"to {hi:g} (e.g. 0.001 for 0.1 %)")


def lagged(f: np.ndarray, full_scale, fraction: float, width: float = WIDTH) -> np.ndarray:
    """The loads the sensor's body feels, f + z, for a load path f of shape (n, N).

    Rows are consecutive samples of one path (the load moves monotonically between
    them), starting from no load history.
    """
    f = np.asarray(f, dtype=float)
    if fraction == 0.0 or f.size == 0:
        return f.copy()
    fs = np.asarray(full_scale, dtype=float)
    r, lam = 0.5 * fraction * fs, width * fs
    df = np.diff(f, axis=0, prepend=np.zeros((1, f.shape[1])))
    decay = np.exp(-np.abs(df) / lam)
    target = -np.sign(df) * r
    z = np.zeros(f.shape[1])
    out = np.empty_like(f)
    for i in range(f.shape[0]):  # a recursion: each sample's lag starts from the last one's
        moving = df[i] != 0.0
        z = np.where(moving, target[i] + (z - target[i]) * decay[i], z)
        out[i] = f[i] + z
    return out


def up_and_down(grid: np.ndarray) -> np.ndarray:
    """A sweep out along ``grid`` and back: -100 .. 100 .. -100 for -100 .. 100."""
    return np.concatenate([grid, grid[-2::-1]])
