"""Sweeps and zero correction.

A *sweep* is one (repetition, loaded axis) series of a single-axis calibration
(Section 3).  Each sweep's voltages are zero-corrected by subtracting the mean
voltages of its zero-load rows; task data are zeroed by a tare or by given offsets.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..axes import DEFAULT, Layout
from ..errors import InputError, where

if TYPE_CHECKING:
    import pandas as pd


def stack(table: pd.DataFrame, names) -> np.ndarray:
    """``table[list(names)].to_numpy()`` without building the sub-frame (a tenth of its cost):
    the columns stacked column-major, as pandas stacks them, so that sums over them round
    alike."""
    return np.vstack([table[c].to_numpy() for c in names]).T


def loaded_axes(forces: np.ndarray) -> np.ndarray:
    """Index of the single non-zero force per row, -1 for a zero-load row.

    Raises nothing: rows with more than one non-zero force get -2.
    """
    nonzero = forces != 0.0
    count = nonzero.sum(axis=1)
    idx = np.where(count == 1, np.argmax(nonzero, axis=1), -1)
    return np.where(count > 1, -2, idx)


def assign_sweeps(table: pd.DataFrame, layout: Layout = DEFAULT,
                  combined: bool = False, full_scale=None) -> pd.DataFrame:
    """Check that each row loads one axis at most and give every row its sweep axis.

    With an ``axis`` column, a row's load must lie on that axis.  Without one, the
    sweeps are inferred from consecutive rows: a zero-load row joins the sweep it
    leads (the next loaded row of the same repetition), and trailing zero-load rows
    join the sweep before them.  A row loading two components at once (a
    combined load: a force at a lever arm is Fy and Mx together) is refused here,
    for fitting.  With ``combined`` (``validate``) such rows are kept: they belong
    to their labelled sweep, or without labels to the sweep they continue (a
    first row to its largest load).
    """
    table = table.copy()
    loads, labels = layout.loads, layout.labels
    forces = stack(table, loads)
    loaded = loaded_axes(forces)
    two = np.flatnonzero(loaded == -2)
    if full_scale is not None and two.size:
        # a calibration row loading several components (a moment on a lever arm) joins the
        # sweep of a load never applied alone (the moment; its force has a sweep of its own),
        # of those the largest relative to its full scale (fitting/joint.py)
        loaded = loaded.copy()
        alone = np.zeros(len(loads), dtype=bool)
        alone[loaded[loaded >= 0]] = True
        rel = np.abs(forces[two]) / np.asarray(full_scale, dtype=float)
        rel = np.where(alone & (rel > 0).any(axis=0) & (rel * ~alone > 0).any(axis=1)[:, None],
                       0.0, rel)
        loaded[two] = np.argmax(rel, axis=1)
        if not np.isin(np.arange(len(loads)), loaded).all():
            # poses of a mass (every row loads every component): a row belongs to the
            # component it loads most relative to that component's peak in the set, so
            # every component has rows to be scored on (as init pairs outputs)
            peak = np.abs(forces).max(axis=0)
            rel = np.abs(forces[two]) / np.where(peak > 0, peak, np.inf)
            loaded[two] = np.argmax(rel, axis=1)
            # a component never the largest (a small moment beside a weight's forces) takes
            # the rows it loads most, from components that keep two rows or more
            for c in np.flatnonzero(peak > 0):
                for r in np.argsort(-rel[:, c], kind="stable")[:2]:
                    if not (loaded[two] == c).sum() < 2:
                        break
                    if (loaded[two] == loaded[two[r]]).sum() > 2 and rel[r, c] > 0:
                        loaded[two[r]] = c
        two = two[:0]
    if combined and two.size:
        loaded = loaded.copy()
        loaded[two] = np.argmax(np.abs(forces[two]), axis=1)  # overridden by a label below
        two = two[:0]
    if two.size:
        i = int(two[0])
        cols = [c for c, v in zip(loads, forces[i], strict=True) if v != 0]
        sweep = f" (the {table['axis'].iat[i]} sweep)" if table["axis"].iat[i] else ""
        raise InputError(
            f"{where(table['file'].iat[i], int(table['row'].iat[i]), cols[1])}: "
            f"row loads {' and '.join(cols)} at once{sweep}; a calibration row loads one axis "
            "(a combined-load sweep cannot be fitted; validating a model, or cv's task log, accepts it)"
        )
    cells = table["axis"].to_numpy()
    if (cells != "").all():
        number = {a: k for k, a in enumerate(labels)}
        labelled = np.array([number.get(a, np.nan) for a in cells])  # as Series.map: NaN if none
        single = (forces != 0.0).sum(axis=1) == 1  # a combined row may load its label and more
        wrong = np.flatnonzero(single & (loaded != labelled))
        if wrong.size:
            i = int(wrong[0])
            col = loads[loaded[i]]
            raise InputError(
                f"{where(table['file'].iat[i], int(table['row'].iat[i]), col)}: "
                f"row loads {col} but its axis is '{table['axis'].iat[i]}'"
            )
        if not combined:
            _refuse_contradicting_rows(table, forces, labelled, loads)
        return table
    axis = np.empty(len(table), dtype=object)
    _, first, group = np.unique(table["repetition"].to_numpy(), return_index=True,
                                return_inverse=True)
    rows_of = rows_by_group(group.ravel())
    for g in np.argsort(first):  # each repetition's rows, repetitions in order of appearance
        idx = rows_of[g]
        pending: list[int] = []
        last = -1
        for i in idx:
            if loaded[i] < 0:
                pending.append(i)
                continue
            last = loaded[i]
            for j in pending:
                axis[j] = labels[last]
            pending = []
            axis[i] = labels[last]
        if last < 0:
            i = int(idx[0])
            raise InputError(
                f"{where(table['file'].iat[i])}: repetition {table['repetition'].iat[i]} "
                "has only zero-load rows, so no sweep can be told apart"
            )
        for j in pending:
            axis[j] = labels[last]
    table["axis"] = axis
    return table


def _refuse_contradicting_rows(table: pd.DataFrame, forces: np.ndarray, labelled: np.ndarray,
                               loads) -> None:
    """A row loading several components in a sweep whose other rows load its label alone.

    Joint fitting is for sweeps that load several components by design (a force on a
    lever arm is a moment too: every row of that sweep loads both).  In a single-axis
    sweep, an x row with fy = 10 contradicts its own axis label: a data-entry error,
    refused naming both loads (``--exclude FILE:ROW`` drops it).
    """
    multi = np.flatnonzero((forces != 0.0).sum(axis=1) > 1)
    if not multi.size:
        return
    alone = (forces != 0.0).sum(axis=1) == 1
    sweep = table["repetition"].astype(str).to_numpy() + "\0" + table["axis"].astype(str).to_numpy()
    for i in multi:
        mine = sweep == sweep[i]
        n_alone, n_multi = int((mine & alone).sum()), int((mine & ~alone & (forces != 0.0).any(axis=1)).sum())
        if n_alone <= n_multi:
            continue  # the sweep loads several components by design
        own = loads[labelled[i]]
        other = [c for c, v in zip(loads, forces[i], strict=True) if v != 0.0 and c != own]
        shown = " and ".join(f"{c} = {forces[i, loads.index(c)]:g}" for c in (own, *other))
        raise InputError(
            f"{where(table['file'].iat[i], int(table['row'].iat[i]))}: the "
            f"'{table['axis'].iat[i]}' sweep's row loads {shown}, but the other {n_alone} "
            f"loaded rows of that sweep load {own} alone: a row that contradicts its own axis "
            "label (a typo?); correct it, or exclude it",
            remedy=("exclude", f"{Path(str(table['file'].iat[i])).name}:{int(table['row'].iat[i])}")
        )


def zero_correct(table: pd.DataFrame, layout: Layout = DEFAULT,
                 method: str = "rows") -> tuple[pd.DataFrame, pd.DataFrame]:
    """Subtract each sweep's zero offsets (Section 3: "zero-corrected").

    ``method="rows"``: the mean outputs of the sweep's zero-load rows.
    ``method="fit"``: offsets estimated from all points (:func:`fitted_offsets`).
    Returns the corrected points (raw voltages kept as ``ux_raw`` ...) and the
    offsets removed, one row per (repetition, axis) sweep.
    """
    import pandas as pd

    outputs = layout.outputs
    zero = (stack(table, layout.loads) == 0.0).all(axis=1)
    # one pass over all sweeps: a write per sweep would copy the columns each time,
    # which made a set of thousands of repetitions quadratic
    sweep, keys = sweeps(table)
    n_all = np.bincount(sweep, minlength=len(keys))
    n_zero = np.bincount(sweep[zero], minlength=len(keys))
    # zeroed by the zero row before (rows loading several components), a sweep needs no
    # zero row of its own, only its repetition does
    before = method == "before" and zero.any()
    bad = np.flatnonzero(((n_zero == 0) & (not before)) | (n_zero == n_all))
    if bad.size:
        g = int(bad[0])
        i = int(np.argmax(sweep == g))
        rep, axis = keys[g]
        what = (f"{where(table['file'].iat[i])}: the {axis} sweep of repetition {rep} "
                f"(from row {table['row'].iat[i]})")
        if n_zero[g] == 0:
            raise InputError(f"{what} has no zero-load row ({' = '.join(layout.loads)} = 0), so it "
                             "cannot be zero-corrected")
        raise InputError(f"{what} has only zero-load rows; a sweep needs loaded points")
    # each sweep's zero rows in file order, side by side: the mean of a contiguous
    # run is the same pairwise sum, divided by the count, as pandas' mean of them
    rows = np.flatnonzero(zero)[np.argsort(sweep[zero], kind="stable")]
    starts = np.concatenate(([0], np.cumsum(n_zero)[:-1]))
    u = stack(table, outputs).astype(float, copy=False)
    mean = np.empty((len(keys), len(outputs)))
    for k in range(len(outputs)):
        col = np.ascontiguousarray(u[rows, k])
        for g, (s, n) in enumerate(zip(starts, n_zero, strict=True)):
            mean[g, k] = col[s:s + n].sum() / n if n else np.nan
    if method == "fit":
        mean = fitted_offsets(table, sweep, keys, layout, mean)
    if method == "before":
        base = zero_before(table["repetition"].to_numpy(), zero)
        corrected = u - u[base]
        # the offsets table: the mean zero each sweep's rows had removed
        mean = np.array([u[base[sweep == g]].mean(axis=0) for g in range(len(keys))])
    else:
        corrected = u - mean[sweep]
    # the table's columns, the outputs corrected, then the raw outputs: one frame built once
    columns = {c: table[c].array for c in table.columns}
    columns.update({c: corrected[:, k] for k, c in enumerate(outputs)})
    columns.update({f"{c}_raw": table[c].array for c in outputs})
    points = pd.DataFrame(columns, index=table.index)
    offsets = pd.DataFrame({
        "repetition": [rep for rep, _ in keys], "axis": [axis for _, axis in keys],
        "n_zero": n_zero.astype(int),
        **{c: mean[:, k] for k, c in enumerate(outputs)},
    })
    return points, offsets


def out_and_back(table: pd.DataFrame, layout: Layout = DEFAULT) -> bool:
    """True when a sweep goes out and back: its loads, in file order, turn once and
    revisit loads of the way out (0 .. -150 .. 0 N; -100 .. 100 .. -100 N).

    Such a sweep has twice the points of a one-way sweep for its offset fitted from all
    points (``zero: fit``) and two zero rows taken at different points of its loop;
    on simulated sensors swept out and back, with hysteresis or without, the fitted
    offsets were more accurate (docs/design/tuning.md, "Sweeps out and back").  A
    sweep pasted twice (-100 .. 100, -100 .. 100) turns twice and is not one.
    """
    forces = stack(table, layout.loads)
    sweep, keys = sweeps(table)
    for idx in rows_by_group(sweep):
        _, label = keys[sweep[idx[0]]]
        if label not in layout.labels:
            continue
        f = forces[idx, layout.labels.index(label)]
        steps = np.sign(np.diff(f))
        steps = steps[steps != 0]
        if steps.size and np.count_nonzero(np.diff(steps)) == 1 and np.unique(f).size < f.size:
            return True
    return False


def sweeps(table: pd.DataFrame) -> tuple[np.ndarray, list]:
    """Each row's sweep number and the sweeps' (repetition, axis) keys, sorted, as
    ``table.groupby(["repetition", "axis"], sort=True)`` numbers and lists them."""
    reps, rep_of = np.unique(table["repetition"].to_numpy(), return_inverse=True)
    axes, axis_of = np.unique(table["axis"].to_numpy(), return_inverse=True)
    codes, sweep = np.unique(rep_of.ravel() * len(axes) + axis_of.ravel(), return_inverse=True)
    keys = [(reps[c // len(axes)], axes[c % len(axes)]) for c in codes]
    return sweep.ravel(), keys


def rows_by_group(group: np.ndarray) -> list[np.ndarray]:
    """The row indices of each group number 0, 1, ... (as np.unique's inverse numbers
    them, every number used), each in file order: one stable sort, where a mask per
    group over the whole table was quadratic in the groups (3,000 repetition files cost
    10^2 times 300)."""
    if not group.size:
        return []
    order = np.argsort(group, kind="stable")
    return np.split(order, np.flatnonzero(np.diff(group[order])) + 1)


def zero_before(repetition: np.ndarray, zero: np.ndarray) -> np.ndarray:
    """Each row's zero: the nearest zero-load row before it in its repetition (file order),
    or for rows before the first one, that first zero row."""
    idx = np.arange(zero.size)
    last = np.maximum.accumulate(np.where(zero, idx, -1))
    start = np.r_[True, repetition[1:] != repetition[:-1]]
    first_of = np.maximum.accumulate(np.where(start, idx, 0))  # the repetition's first row
    base = np.where(last >= first_of, last, -1)
    for r in np.flatnonzero(base < 0):  # before any zero row of its repetition: the next one
        after = np.flatnonzero(zero[r:] & (repetition[r:] == repetition[r]))
        base[r] = r + after[0] if after.size else r
    return base


MAX_DEGREE = 5  # of the shared polynomial in fitted_offsets


def fitted_offsets(points: pd.DataFrame, sweep: np.ndarray, keys: list, layout: Layout,
                   rows_mean: np.ndarray) -> np.ndarray:
    """Each sweep's output offsets from all its points, jointly over the repetitions.

    One zero-load row per sweep leaves its noise in every point of the sweep, and
    every chi_ab inherits the mean of those shifts over the repetitions (about
    sigma / sqrt(reps)); an output sums N - 1 of them (eq. 11).  Here, for every
    loaded component b and output a, the raw outputs of all b sweeps are fitted
    by least squares as ``u_a = c_rep + sum_{p=1..d} beta_p s^p`` with
    s = f_b / max|f_b|: one offset per sweep and one shape, which is 0 at zero
    load (chi(0) = 0, omega through the origin) and polynomial of degree
    d = min(5, levels - 2).  Each offset then rests on all the sweep's points,
    not its zero rows alone.  Components with too few load levels keep
    ``rows_mean``, the zero rows' mean.
    """
    out = rows_mean.copy()
    axis_of_key = np.array([axis for _, axis in keys], dtype=object)
    labels = points["axis"].to_numpy()
    u = points[list(layout.outputs)].to_numpy(dtype=float)
    for b, label in enumerate(layout.labels):
        idx = np.flatnonzero(labels == label)
        f = points[layout.loads[b]].to_numpy(dtype=float)[idx]
        groups = np.flatnonzero(axis_of_key == label)  # this component's sweeps
        design = offset_design(f, np.searchsorted(groups, sweep[idx]), groups.size)
        if design is None:
            continue
        coef, *_ = np.linalg.lstsq(design, u[idx], rcond=None)
        out[groups] = coef[:groups.size]
    return out


def offset_design(f: np.ndarray, col: np.ndarray, groups: int) -> np.ndarray | None:
    """The design of :func:`fitted_offsets` for one component's points of loads ``f``:
    one column per sweep (``col`` each point's, of ``groups``), then s^1..s^d, s = f over
    the largest |f|, d up to MAX_DEGREE and two below the number of load levels; None
    where the offsets cannot be fitted (too few levels, no load)."""
    degree = min(MAX_DEGREE, np.unique(f).size - 2)
    peak = np.abs(f).max(initial=0.0)
    if degree < 1 or not peak > 0:
        return None
    return sweep_design(f / peak, col, groups, degree)


def sweep_design(s: np.ndarray, col: np.ndarray, groups: int, degree: int) -> np.ndarray:
    """One column per sweep (``col`` each point's, of ``groups``), then s^1..s^degree:
    a sweep's offset and the shape all its sweeps share."""
    return np.column_stack([np.eye(groups)[col], *(s ** p for p in range(1, degree + 1))])


def mean_offset_variance(points: pd.DataFrame, layout: Layout) -> np.ndarray:
    """Per loaded component b, the variance of the mean of its sweeps' zero readings, in
    units of one reading's variance: mean_g(1 / m_g) / G over its G sweeps of m_g zero
    rows each (NaN: a sweep without one).

    With zero rows every chi_ab (and omega_b) is fitted to the b sweeps less their zero
    readings, so it inherits their mean error, the same at every loaded point
    (``fitted_offsets``): one realisation per calibration, which no held-out round shows.
    """
    labels = points["axis"].to_numpy()
    out = np.full(layout.n, np.nan)
    for b, label in enumerate(layout.labels):
        mine = points[labels == label]
        _, sweep = np.unique(mine["repetition"].to_numpy(), return_inverse=True)
        groups = sweep.max(initial=-1) + 1
        zero = (mine[list(layout.loads)].to_numpy() == 0.0).all(axis=1)
        n_zero = np.bincount(sweep[zero], minlength=groups)
        if groups and n_zero.min() > 0:
            out[b] = float(np.mean(1.0 / n_zero)) / groups
    return out


def zero_row_shift(points: pd.DataFrame, offsets: pd.DataFrame,
                   layout: Layout) -> tuple[np.ndarray, np.ndarray]:
    """What the zero rows left in a model, as the offsets fitted from all points see it.

    Returns ``(shift, ratio)``: ``shift[b, a]`` the mean over the b sweeps of
    (fitted offset - zero rows' offset) of output a [output unit], the error every
    chi_ab inherits (:func:`fitted_offsets`); ``ratio[b]`` = sum f_b / sum f_b^2 over
    the b sweeps' points [1/load unit], by which omega_b's slope, a least-squares fit
    through the origin (eq. 2), takes up shift[b, b].  ``points``: zero-corrected by
    their zero rows with the raw outputs kept (``ux_raw`` ...); ``offsets``: those rows'.
    """
    outputs = list(layout.outputs)
    table = points.drop(columns=outputs).rename(columns={f"{c}_raw": c for c in outputs})
    _, fitted = zero_correct(table, layout, "fit")
    diff = fitted[outputs].to_numpy(dtype=float) - offsets[outputs].to_numpy(dtype=float)
    axis = offsets["axis"].to_numpy()
    shift, ratio = np.zeros((layout.n, len(outputs))), np.zeros(layout.n)
    for b, label in enumerate(layout.labels):
        if (axis == label).any():
            shift[b] = diff[axis == label].mean(axis=0)
        f = points.loc[points["axis"] == label, layout.loads[b]].to_numpy(dtype=float)
        ratio[b] = f.sum() / (f @ f) if f @ f > 0 else 0.0
    return shift, ratio


def shift_variance(points: pd.DataFrame, layout: Layout) -> np.ndarray:
    """Per loaded component b, the variance of what :func:`zero_row_shift` leaves of
    the zero readings' mean error, in units of one reading's variance.

    The shift is mean_g (c_hat_g - z_g): z_g the zero rows' mean of sweep g, c_hat_g its
    offset fitted from all points (:func:`fitted_offsets`).  With the sweep's true
    offset c_g, c_hat_g = c_g + delta_g and z_g = c_g + eps_g, so the shift is
    mean_g delta_g - mean_g eps_g: the inherited error (- mean_g eps_g) plus the fit's own
    error, which the centre keeps.  For independent readings of equal variance and a
    shape the polynomial holds, Var(mean_g delta_g) = a' (X'X)^-1 a, X the design of
    :func:`fitted_offsets` (one column per sweep, then s^1..s^d) and a = 1/G on the G
    sweeps' columns (Gauss-Markov).  A component whose offsets are not fitted (too few
    load levels) keeps its zero rows': nothing is shifted, and all of
    :func:`mean_offset_variance` is left.  NaN where a sweep has no zero row.
    """
    out = mean_offset_variance(points, layout)
    labels = points["axis"].to_numpy()
    for b, label in enumerate(layout.labels):
        mine = points[labels == label]
        if not np.isfinite(out[b]):
            continue
        _, col = np.unique(mine["repetition"].to_numpy(), return_inverse=True)
        groups = col.max() + 1
        design = offset_design(mine[layout.loads[b]].to_numpy(dtype=float), col, groups)
        if design is None:
            continue
        a = np.concatenate([np.full(groups, 1.0 / groups), np.zeros(design.shape[1] - groups)])
        out[b] = float(a @ np.linalg.lstsq(design.T @ design, a, rcond=None)[0])
    return out


def tare_offsets(u: np.ndarray, n: int, source=None) -> np.ndarray:
    """Mean of the first ``n`` voltage rows, the zero of a task log [V]."""
    src = f"{source}: " if source is not None else ""
    if n < 1:
        raise InputError(f"a tare needs at least 1 row, got {n}", argument="tare")
    if len(u) < n:
        raise InputError(f"{src}tare of {n} rows: the log has only {len(u)} rows", argument="tare")
    head = u[:n]
    if not np.isfinite(head).all():
        bad = int(np.argmax(~np.isfinite(head).all(axis=1))) + 2
        raise InputError(
            f"{src}tare of {n} rows: the first {n} rows contain missing values (row {bad}); "
            "the zero needs complete rows", argument="tare"
        )
    return head.mean(axis=0)


# Singular values of the intercept design below this fraction of the largest: the offsets
# and the loads cannot be told apart (a double's rounding of full-scale loads is 1e-16).
SEPARABLE = 1e-6


def has_zero_row(table: pd.DataFrame, layout: Layout = DEFAULT) -> bool:
    """Whether any row of the set is unloaded (every applied load 0)."""
    return bool((stack(table, layout.loads) == 0.0).all(axis=1).any())


def intercept_offsets(table: pd.DataFrame, layout: Layout, full_scale,
                      source: str) -> tuple[pd.DataFrame, pd.DataFrame]:
    """``zero: intercept``: each output's offset fitted as an unknown with the loads.

    A set without an unloaded row (poses of a known mass: gravity never switches off) has
    no zero to subtract, so each output u_j is fitted by least squares as

        u_j = c_j,rep + sum_a K_ja f_a

    one offset c per output and repetition, one linear response K shared by the
    repetitions, as in-situ calibration does; the offsets are then subtracted like a
    zero row's mean (Section 3's zero correction), and eq. (2)'s omega and the chi are
    fitted to the corrected outputs as before.  Refused by name when the offsets and
    the loads cannot be separated (every row the same load; a load that moves with the
    intercept): a rank-deficient design.

    Returns the corrected points (raw outputs kept as ``<output>_raw``) and the offsets,
    one row per repetition, ``axis`` empty and ``n_zero`` 0 [output units].
    """
    import pandas as pd

    outputs, loads = list(layout.outputs), list(layout.loads)
    points = table.copy()
    for c in outputs:
        points[f"{c}_raw"] = points[c]
    reps = points["repetition"].to_numpy()
    keys, index = np.unique(reps, return_inverse=True)
    f = points[loads].to_numpy(dtype=float) / np.asarray(full_scale, dtype=float)
    design = np.column_stack([np.eye(keys.size)[index], f])
    same = np.ptp(f, axis=0).max(initial=0.0) == 0.0
    _, sv, vt = np.linalg.svd(design, full_matrices=False)
    if same or len(design) < design.shape[1] or sv[-1] < SEPARABLE * sv[0]:
        if same:
            first = points[loads].iloc[0]
            why = f"every row has the same loads ({', '.join(f'{c} {first[c]:g}' for c in loads)})"
        elif len(design) < design.shape[1]:
            why = (f"{len(design)} rows for {design.shape[1]} unknowns (an offset per output "
                   f"and repetition and a slope per load)")
        else:
            v = vt[-1][keys.size:]
            tied = [loads[a] for a in np.flatnonzero(np.abs(v) > 0.1 * np.abs(vt[-1]).max())]
            why = (f"{' and '.join(tied) or 'the loads'} move{'s' if len(tied) == 1 else ''} "
                   "with the offset in every row (a rank-deficient design)")
        raise InputError(f"{source}: zero: intercept cannot separate the outputs' offsets from "
                         f"the loads: {why}; add poses with other loads, or an unloaded row")
    u = points[outputs].to_numpy(dtype=float)
    coef, *_ = np.linalg.lstsq(design, u, rcond=None)
    offsets = coef[:keys.size]  # (repetitions, outputs)
    points[outputs] = u - offsets[index]
    table_out = pd.DataFrame({"repetition": keys.astype(int), "axis": "", "n_zero": 0,
                              **{c: offsets[:, j] for j, c in enumerate(outputs)}})
    return points, table_out
