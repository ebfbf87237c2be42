"""Evaluate saved kernel models with numpy alone (no libsvm at apply time)."""

from __future__ import annotations

import numpy as np

_CHUNK_ELEMENTS = 1 << 20  # bound the (n, n_sv) work array to ~8 MB


def rbf_sum(
    x: np.ndarray, centres: np.ndarray, coef: np.ndarray, gamma: float, bias: float = 0.0
) -> np.ndarray:
    """``sum_i coef_i exp(-gamma (x - c_i)^2) + bias`` for each x (eq. 10 with b = bias).

    Exactly libsvm's RBF prediction for one input when ``coef`` are the dual
    coefficients and ``bias = -rho``.
    """
    x = np.asarray(x, dtype=float)
    flat = x.ravel()
    out = np.empty(flat.size)
    step = max(1, _CHUNK_ELEMENTS // max(1, centres.size))
    for start in range(0, flat.size, step):
        xs = flat[start:start + step, None]
        d = xs - centres[None, :]
        # a row-wise reduction, not BLAS gemv: the result must not depend on how
        # many rows a chunk holds (gemv's blocking changes the last digit)
        out[start:start + step] = (np.exp(-gamma * (d * d)) * coef).sum(axis=1)
    out += bias
    return out.reshape(x.shape)


def rbf_sum_slope(x: np.ndarray, centres: np.ndarray, coef: np.ndarray, gamma: float) -> np.ndarray:
    """d/dx of :func:`rbf_sum`: ``sum_i coef_i (-2 gamma (x - c_i)) exp(-gamma (x - c_i)^2)``."""
    x = np.asarray(x, dtype=float)
    flat = x.ravel()
    out = np.empty(flat.size)
    step = max(1, _CHUNK_ELEMENTS // max(1, centres.size))
    for start in range(0, flat.size, step):
        d = flat[start:start + step, None] - centres[None, :]
        out[start:start + step] = (np.exp(-gamma * (d * d)) * (-2.0 * gamma) * d * coef).sum(axis=1)
    return out.reshape(x.shape)
