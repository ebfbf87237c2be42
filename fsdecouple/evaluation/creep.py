"""The time of each calibration reading, for ISO 376's creep c (config ``creep: {column}``).

A lab that holds each sweep's largest load and reads it 30 s and 300 s after
applying it dates its readings in a column of elapsed time [s].  The calibration
reader keeps only the columns the model needs, so the certificate reads this one
from the set's own files, row by row, and refuses a column that is missing, not a
number, or not time (a reading dated before the one above it).
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pandas as pd

from ..config import Settings
from ..data.calibration import CalibrationSet
from ..data.csv_text import HEADER_ROW, read_csv_text, read_header, to_numbers
from ..errors import InputError, where
from ..files.inputs import CALIBRATION_LIMIT, read_bounded, reading


def creep_times(calib: CalibrationSet, settings: Settings) -> pd.Series | None:
    """Seconds of every point of ``calib`` (indexed like ``calib.points``), or None
    when the config names no creep column."""
    column = settings.lab.creep_column
    if column is None:
        return None
    points = calib.points
    out = pd.Series(np.nan, index=points.index)
    for name, _ in calib.files:
        path = Path(name)
        with reading(path):
            data = read_bounded(path, CALIBRATION_LIMIT, "a calibration file")
        header = read_header(path, settings, data, strict=False)
        if column not in header:
            raise InputError(f"{where(path, HEADER_ROW)}: no column '{column}' (creep: column), "
                             "expected the time of each reading [s]")
        raw = read_csv_text(io.BytesIO(data), settings, path=path, header=0,
                            names=[str(i) for i in range(len(header))])
        cells = raw[str(header.index(column))]
        mine = points["file"].to_numpy() == str(name)
        rows = points.loc[mine, "row"].to_numpy(dtype=int)
        order = np.argsort(rows, kind="stable")
        at = rows[order] - HEADER_ROW - 1  # blank lines are kept: position = row - 2
        t = to_numbers(cells.iloc[at].reset_index(drop=True), path, column, rows[order],
                       settings.decimal)
        back = np.flatnonzero(np.diff(t) < 0)
        if back.size:
            i = int(back[0]) + 1
            raise InputError(f"{where(path, int(rows[order][i]), column)}: {t[i]:g} after "
                             f"{t[i - 1]:g} in the row above; expected time, which never goes back "
                             "(creep: column)")
        out.loc[points.index[mine][order]] = t
    return out
