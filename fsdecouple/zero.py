"""Sweeps and zero correction.

A *sweep* is one (repetition, loaded axis) series of a single-axis calibration
(Section 3).  Each sweep's voltages are zero-corrected by subtracting the mean
voltages of its zero-load rows; task data are zeroed by a tare or by given offsets.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .axes import AXES, FORCE_COLUMNS, VOLTAGE_COLUMNS
from .errors import InputError, where

if TYPE_CHECKING:
    import pandas as pd


def loaded_axes(forces: np.ndarray) -> np.ndarray:
    """Index of the single non-zero force per row, -1 for a zero-load row.

    Raises nothing: rows with more than one non-zero force get -2.
    """
    nonzero = forces != 0.0
    count = nonzero.sum(axis=1)
    idx = np.where(count == 1, np.argmax(nonzero, axis=1), -1)
    return np.where(count > 1, -2, idx)


def assign_sweeps(table: pd.DataFrame) -> pd.DataFrame:
    """Check that each row loads one axis at most and give every row its sweep axis.

    With an ``axis`` column, a row's load must lie on that axis.  Without one, the
    sweeps are inferred from consecutive rows: a zero-load row joins the sweep it
    leads (the next loaded row of the same repetition), and trailing zero-load rows
    join the sweep before them.
    """
    table = table.copy()
    forces = table[list(FORCE_COLUMNS)].to_numpy()
    loaded = loaded_axes(forces)
    two = np.flatnonzero(loaded == -2)
    if two.size:
        i = int(two[0])
        cols = [c for c, v in zip(FORCE_COLUMNS, forces[i], strict=True) if v != 0]
        raise InputError(
            f"{where(table['file'].iat[i], int(table['row'].iat[i]), cols[1])}: "
            f"row loads {' and '.join(cols)} at once; a calibration row loads one axis"
        )
    if (table["axis"] != "").all():
        labelled = table["axis"].map({a: k for k, a in enumerate(AXES)}).to_numpy()
        wrong = np.flatnonzero((loaded >= 0) & (loaded != labelled))
        if wrong.size:
            i = int(wrong[0])
            col = FORCE_COLUMNS[loaded[i]]
            raise InputError(
                f"{where(table['file'].iat[i], int(table['row'].iat[i]), col)}: "
                f"row loads {col} but its axis is '{table['axis'].iat[i]}'"
            )
        return table
    axis = np.empty(len(table), dtype=object)
    for _, idx in table.groupby("repetition", sort=False).indices.items():
        pending: list[int] = []
        last = -1
        for i in idx:
            if loaded[i] < 0:
                pending.append(i)
                continue
            last = loaded[i]
            for j in pending:
                axis[j] = AXES[last]
            pending = []
            axis[i] = AXES[last]
        if last < 0:
            i = int(idx[0])
            raise InputError(
                f"{where(table['file'].iat[i])}: repetition {table['repetition'].iat[i]} "
                "has only zero-load rows, so no sweep can be told apart"
            )
        for j in pending:
            axis[j] = AXES[last]
    table["axis"] = axis
    return table


def zero_correct(table: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Subtract each sweep's mean zero-load voltages (Section 3: "zero-corrected").

    Returns the corrected points (raw voltages kept as ``ux_raw`` ...) and the
    offsets removed, one row per (repetition, axis) sweep.
    """
    import pandas as pd

    points = table.copy()
    for c in VOLTAGE_COLUMNS:
        points[f"{c}_raw"] = points[c]
    zero = (points[list(FORCE_COLUMNS)] == 0.0).all(axis=1).to_numpy()
    # one pass over all sweeps: a write per sweep would copy the columns each time,
    # which made a set of thousands of repetitions quadratic
    grouped = points.groupby(["repetition", "axis"], sort=True)
    sweep = grouped.ngroup().to_numpy()
    keys = list(grouped.groups)  # (repetition, axis), sorted as ngroup numbers them
    n_all = np.bincount(sweep, minlength=len(keys))
    n_zero = np.bincount(sweep[zero], minlength=len(keys))
    bad = np.flatnonzero((n_zero == 0) | (n_zero == n_all))
    if bad.size:
        g = int(bad[0])
        first = points.iloc[int(np.argmax(sweep == g))]
        rep, axis = keys[g]
        what = f"{where(first['file'])}: the {axis} sweep of repetition {rep} (from row {first['row']})"
        if n_zero[g] == 0:
            raise InputError(f"{what} has no zero-load row (fx = fy = fz = 0), so it cannot be "
                             "zero-corrected")
        raise InputError(f"{what} has only zero-load rows; a sweep needs loaded points")
    # each sweep's zero rows in file order, side by side: the mean of a contiguous
    # run is the same pairwise sum, divided by the count, as pandas' mean of them
    rows = np.flatnonzero(zero)[np.argsort(sweep[zero], kind="stable")]
    starts = np.concatenate(([0], np.cumsum(n_zero)[:-1]))
    u = points[list(VOLTAGE_COLUMNS)].to_numpy(dtype=float)
    mean = np.empty((len(keys), len(VOLTAGE_COLUMNS)))
    for k in range(len(VOLTAGE_COLUMNS)):
        col = np.ascontiguousarray(u[rows, k])
        for g, (s, n) in enumerate(zip(starts, n_zero, strict=True)):
            mean[g, k] = col[s:s + n].sum() / n
    for k, c in enumerate(VOLTAGE_COLUMNS):
        points[c] = u[:, k] - mean[sweep, k]
    offsets = pd.DataFrame({
        "repetition": [rep for rep, _ in keys], "axis": [axis for _, axis in keys],
        "n_zero": n_zero.astype(int),
        **{c: mean[:, k] for k, c in enumerate(VOLTAGE_COLUMNS)},
    })
    return points, offsets


def tare_offsets(u: np.ndarray, n: int, source=None) -> np.ndarray:
    """Mean of the first ``n`` voltage rows, the zero of a task log [V]."""
    src = f"{source}: " if source is not None else ""
    if n < 1:
        raise InputError(f"--tare: needs at least 1 row, got {n}")
    if len(u) < n:
        raise InputError(f"{src}--tare {n}: the log has only {len(u)} rows")
    head = u[:n]
    if not np.isfinite(head).all():
        bad = int(np.argmax(~np.isfinite(head).all(axis=1))) + 2
        raise InputError(
            f"{src}--tare {n}: the first {n} rows contain missing values (row {bad}); "
            "the zero needs complete rows"
        )
    return head.mean(axis=0)
