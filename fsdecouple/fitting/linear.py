"""Linear parts: the non-coupling functions omega (eq. 2) by least squares."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..axes import DEFAULT, Layout


@dataclass(frozen=True)
class OmegaFit:
    """Slopes of the non-coupling functions, ``u_aa = k_aa * f_a`` (eq. 2).

    Attributes
    ----------
    k : ndarray, shape (N,)
        k_xx, k_yy, k_zz [V/N].
    r2 : ndarray, shape (N,)
        Coefficient of determination of each fit, ``1 - SS_res / SS_tot`` with
        SS_tot about the mean (the stricter form for a fit through the origin).
    n : ndarray, shape (N,)
        Number of points per axis.
    """

    k: np.ndarray
    r2: np.ndarray
    n: np.ndarray

    @property
    def inverse(self) -> np.ndarray:
        """1/k [N/V]: the form of eq. (13), ``f_x = omega_x^-1(u_x) = (1/k_xx) u_x``."""
        return 1.0 / self.k


def fit_omega(points, layout: Layout = DEFAULT) -> OmegaFit:
    """Least squares through the origin of prime voltage on prime force (Section 2.3, step 2).

    ``points`` is a zero-corrected DataFrame with ``axis``, ``fx..fz`` and ``ux..uz``.
    k = sum(f u) / sum(f^2) minimises sum (u - k f)^2.
    """
    n_c = layout.n
    k, r2, n = np.empty(n_c), np.empty(n_c), np.empty(n_c, dtype=int)
    for a, axis in enumerate(layout.labels):
        s = points[points["axis"] == axis]
        f = s[layout.loads[a]].to_numpy(dtype=float)
        u = s[layout.outputs[a]].to_numpy(dtype=float)
        ff = float(f @ f)
        k[a] = float(f @ u) / ff if ff > 0 else np.nan
        ss_res = float(((u - k[a] * f) ** 2).sum())
        ss_tot = float(((u - u.mean()) ** 2).sum())
        r2[a] = 1.0 - ss_res / ss_tot if ss_tot > 0 else np.nan
        n[a] = f.size
    return OmegaFit(k, r2, n)


@dataclass(frozen=True)
class CalibrationMatrix:
    """The standard industrial linear calibration, ``f = C u`` (Section 1, refs 9-11).

    Attributes
    ----------
    C : ndarray, shape (N, N)
        Calibration matrix [N/V], row a gives f_a from u_x, u_y, u_z.
    """

    C: np.ndarray

    def decouple(self, u: np.ndarray, *, rotate: bool = False) -> np.ndarray:
        """Forces [N] from zero-corrected voltages [V]: ``f = C u`` per row."""
        del rotate  # the baseline works in the sensor frame only
        return np.asarray(u, dtype=float).reshape(-1, self.C.shape[1]) @ self.C.T


def fit_calibration_matrix(u: np.ndarray, f: np.ndarray) -> CalibrationMatrix:
    """Least squares ``F ~ U C^T`` over all training points (the pseudo-inverse method).

    No intercept: the calibration data are zero-corrected, so zero load gives
    zero voltage by construction.  ``u`` and ``f`` have shape (n, N) [V], [N].
    """
    u = np.atleast_2d(np.asarray(u, dtype=float))
    f = np.atleast_2d(np.asarray(f, dtype=float))
    ct, *_ = np.linalg.lstsq(u, f, rcond=None)
    return CalibrationMatrix(np.ascontiguousarray(ct.T))
