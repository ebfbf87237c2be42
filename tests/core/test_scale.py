"""Thousands of repetitions: the zero correction is exact and its work grows linearly.

The reference below is the straightforward per-sweep loop the package used before
(pandas' mean of each sweep's zero-load rows, subtracted sweep by sweep); the
vectorised :func:`fsdecouple.data.zero.zero_correct` must give the same bits.
"""

from __future__ import annotations

import sys

import numpy as np
import pandas as pd
import pytest
from conftest import SAMPLE

from fsdecouple.axes import FORCE_COLUMNS, VOLTAGE_COLUMNS
from fsdecouple.data.calibration import from_table
from fsdecouple.data.calibration_csv import read_calibration_table
from fsdecouple.data.zero import assign_sweeps, zero_correct
from fsdecouple.errors import InputError
from fsdecouple.sim.simulate import SimulatedSensor, simulate, simulate_calibration


def reference_zero_correct(table: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    points = table.copy()
    for c in VOLTAGE_COLUMNS:
        points[f"{c}_raw"] = points[c]
    volts = points[list(VOLTAGE_COLUMNS)].to_numpy(copy=True)
    offsets = []
    for (rep, axis), g in table.groupby(["repetition", "axis"], sort=True):
        first = g.iloc[0]
        sweep = f"{first['file']}: the {axis} sweep of repetition {rep} (from row {first['row']})"
        zero = (g[list(FORCE_COLUMNS)] == 0.0).all(axis=1)
        if not zero.any():
            raise InputError(f"{sweep} has no zero-load row (fx = fy = fz = 0), so it cannot "
                             "be zero-corrected")
        if zero.all():
            raise InputError(f"{sweep} has only zero-load rows; a sweep needs loaded points")
        mean = g.loc[zero, list(VOLTAGE_COLUMNS)].mean()
        for k, c in enumerate(VOLTAGE_COLUMNS):
            volts[table.index.get_indexer(g.index), k] -= mean[c]
        offsets.append({"repetition": rep, "axis": axis, "n_zero": int(zero.sum()),
                        **{c: float(mean[c]) for c in VOLTAGE_COLUMNS}})
    for k, c in enumerate(VOLTAGE_COLUMNS):
        points[c] = volts[:, k]
    return points, pd.DataFrame(offsets)


def assert_same_bits(table):
    points, offsets = zero_correct(table)
    ref_points, ref_offsets = reference_zero_correct(table)
    pd.testing.assert_frame_equal(points, ref_points, check_exact=True)
    pd.testing.assert_frame_equal(offsets, ref_offsets, check_exact=True)
    for c in VOLTAGE_COLUMNS:  # bit for bit, not only equal (-0.0, NaN payloads)
        assert points[c].to_numpy().tobytes() == ref_points[c].to_numpy().tobytes()
        assert offsets[c].to_numpy().tobytes() == ref_offsets[c].to_numpy().tobytes()


def test_zero_correct_bit_identical_on_sample(settings):
    table = assign_sweeps(read_calibration_table(SAMPLE / "calibration", settings).table)
    assert_same_bits(table)


@pytest.mark.slow  # writes and reads 120 repetition files
def test_zero_correct_bit_identical_on_120_files(tmp_path, settings):
    """Many files as the reader gives them: 360 sweeps, repetition numbers of one to three
    digits (file names that sort otherwise as text: rep1, rep10, rep100, ..., rep2).  It
    read 300 files: the same cases at 2.5 times the CPU; how the work grows with the
    repetitions is test_validation_and_zero_correction_work_is_linear's point."""
    simulate(tmp_path, seed=5, repetitions=120)
    table = assign_sweeps(read_calibration_table(tmp_path / "calibration", settings).table)
    assert table["repetition"].nunique() == 120
    assert_same_bits(table)


def test_zero_correct_bit_identical_with_long_zero_runs(settings):
    # numpy sums 8 or more values pairwise, not left to right: sweeps with 1, 7, 9,
    # 200 and 300 zero rows (in no order, between loaded rows) cover both ways
    rng = np.random.default_rng(3)
    rows = []
    for rep, n_zero in enumerate((1, 7, 9, 200, 300), start=1):
        for axis_i, axis in enumerate("xyz"):
            n = n_zero + 20
            f = np.zeros((n, 3))
            loaded = rng.permutation(n)[:20]
            f[loaded, axis_i] = rng.uniform(1, 100, 20)
            u = rng.normal(0, 1e3, (n, 3)) * 10.0 ** rng.integers(-8, 8, (n, 1))
            rows.append(pd.DataFrame({"repetition": rep, "axis": axis, "file": f"rep{rep}.csv",
                                      "row": np.arange(n) + 2,
                                      **dict(zip(FORCE_COLUMNS, f.T, strict=True)),
                                      **dict(zip(VOLTAGE_COLUMNS, u.T, strict=True))}))
    # interleave sweeps and repetitions so a sweep's rows are not contiguous
    table = pd.concat(rows, ignore_index=True).sample(frac=1, random_state=1)
    table = table.sort_values("repetition", kind="stable").reset_index(drop=True)
    assert_same_bits(table)


@pytest.mark.parametrize("broken", ["no zero row", "only zero rows"])
def test_zero_correct_errors_as_reference(broken, settings):
    table = assign_sweeps(read_calibration_table(SAMPLE / "calibration", settings).table)
    sweep = np.flatnonzero((table["repetition"] == 4).to_numpy()
                           & (table["axis"] == "y").to_numpy())
    if broken == "no zero row":
        zero = sweep[(table.loc[sweep, list(FORCE_COLUMNS)] == 0).all(axis=1).to_numpy()]
        table.loc[zero, "fy"] = 1.0
    else:
        table.loc[sweep, "fy"] = 0.0
    with pytest.raises(InputError) as ref:
        reference_zero_correct(table)
    with pytest.raises(InputError, match="the y sweep of repetition 4") as got:
        zero_correct(table)
    assert str(got.value) == str(ref.value)


def rows_touched(fn) -> int:
    """Work by ``fn()``: the length of every Series or DataFrame a pandas method runs on."""
    total = 0

    def hook(frame, event, arg):
        nonlocal total
        if event == "call" and "/pandas/" in frame.f_code.co_filename:
            obj = frame.f_locals.get("self")
            if isinstance(obj, pd.Series | pd.DataFrame) and "_mgr" in vars(obj):
                total += len(obj)  # (not while it is being built)

    sys.setprofile(hook)
    try:
        fn()
    finally:
        sys.setprofile(None)
    return total


def test_validation_and_zero_correction_work_is_linear(settings):
    # a pandas operation on the whole table per repetition or per sweep made
    # thousands of repetitions quadratic: ten times the repetitions must cost
    # about ten times the work (linear), not a hundred
    sensor = SimulatedSensor()
    work = []
    for reps in (20, 200):
        table = simulate_calibration(sensor, repetitions=reps, seed=1)
        table = table.assign(file=[f"rep{r}.csv" for r in table["repetition"]],
                             row=np.arange(len(table)) + 2)
        work.append(rows_touched(lambda t=table: from_table(t, settings)))
    assert work[1] <= 12 * work[0], work
