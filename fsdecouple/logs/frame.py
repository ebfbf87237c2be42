"""eq. (11) over a pandas DataFrame: the pure function any engine can call.

:func:`decouple_frame` takes the output columns of a log as a DataFrame and
returns the same rows with ``fx, fy, fz`` (in the model's load unit) and
``status`` appended, by the rules :mod:`fsdecouple.logs.apply` writes a log with:
the very function that sets the status of ``apply``'s rows
(:func:`fsdecouple.logs.apply.decouple_rows`: the same statuses, range margin,
limits and table path of eq. (11), one thread per call).  So a log decoupled in
partitions by Dask (``map_partitions``), by Spark (``mapInPandas``) or in a
notebook gets the forces ``apply --round-trip`` writes, to the last bit.

A DataFrame has no text, so ``truncated`` (a cut-off last line) never occurs;
the parsing is the caller's (``pandas.read_csv`` of pandas 3 reads the same
doubles as ``apply``'s parser; the tests check it on the sample log).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..core.model import CouplingErrorModel
from ..data.zero import tare_offsets
from ..errors import InputError
from ..evaluation.intervals import half_widths, interval_names, with_intervals
from ..temperature_units import column as temperature_column
from ..temperature_units import to_celsius
from ..temperature_units import unit as temperature_unit
from .apply import STATUS_COLUMN, STATUSES, RowRules, check_options, decouple_rows
from .outputs import input_names, input_scale

if TYPE_CHECKING:
    import pandas as pd

    from ..config import Settings

_NAMES = np.array(list(STATUSES), dtype=object)


def frame_outputs(model: CouplingErrorModel, frame: pd.DataFrame,
                  settings: Settings | None = None) -> np.ndarray:
    """The outputs u_x, u_y, u_z of ``frame`` after the config's ``scale``, shape (n, N).

    Columns by the config's names (``settings``, default the model's:
    ``model.settings.columns['ux']`` ...);
    missing values (NaN, None, pandas NA) stay NaN; text that is not a number and
    an infinite value are errors naming the row, as in ``apply``.
    """
    import pandas as pd

    settings = settings or model.settings
    layout = model.layout
    names = [settings.columns[c] for c in layout.outputs]
    if model.n_inputs > model.n_outputs:  # a fitted model's temperature (logs/outputs.py)
        names.append(temperature_column(settings) or temperature_column(model.settings)
                     or "temperature")
    absent = [n for n in names if n not in frame.columns]
    if absent:
        raise InputError(f"the frame has no column '{absent[0]}' (columns: "
                         f"{', '.join(map(str, frame.columns))})")
    clash = [c for c in (*layout.loads, STATUS_COLUMN) if c in frame.columns]
    if clash:
        raise InputError(f"the frame already has a column named '{clash[0]}', which the output "
                         "would overwrite")
    cols = []
    for name in names:
        col = frame[name]
        values = pd.to_numeric(col, errors="coerce").to_numpy(dtype=float, na_value=np.nan)
        bad = (np.isnan(values) & col.notna().to_numpy()) | np.isinf(values)
        if bad.any():
            i = int(np.argmax(bad))
            raise InputError(f"frame row {frame.index[i]!r}, column '{name}': "
                             f"{col.iloc[i]!r}, expected a number")
        cols.append(values)
    if model.n_inputs > model.n_outputs:
        cols[-1] = to_celsius(cols[-1], temperature_unit(settings if temperature_column(settings)
                                                         else model.settings))
    # C order, as apply's parsed blocks: the tare's mean then sums in the same order
    return np.ascontiguousarray(np.column_stack(cols)) * input_scale(model, settings)


def frame_tare(model: CouplingErrorModel, frame: pd.DataFrame, n: int,
               settings: Settings | None = None) -> np.ndarray:
    """The zero of a log [output unit]: the mean outputs of its first ``n`` rows.

    For engines that cut a log into partitions: compute the zero once, from the
    log's head, and pass it to every partition as ``decouple_frame(..., zero=...)``.
    """
    return tare_offsets(frame_outputs(model, frame.iloc[:n], settings), n)


def decouple_frame(model: CouplingErrorModel, frame: pd.DataFrame, *, tare: int | None = None,
                   zero=None, settings: Settings | None = None,
                   interval: float | None = None) -> pd.DataFrame:
    """Forces by eq. (11) for every row of ``frame``; the rows and columns unchanged.

    Parameters
    ----------
    model : CouplingErrorModel
        A loaded model (:func:`fsdecouple.load_model`).
    frame : pandas.DataFrame
        Outputs by the model's config column names and units (``scale`` is applied).
    tare : int, optional
        Subtract the mean outputs of the first ``tare`` rows *of this frame*.
    zero : array_like, shape (N,), optional
        Subtract these outputs instead [output unit].
    settings : Settings, optional
        Column names, ``scale`` and ``limits`` of the frame (``apply -c CONFIG``);
        default: the model's.  Its units must be the model's.
    interval : float, optional
        Also ``fx_lo, fx_hi, ...``: bounds holding the true force with probability
        ``interval`` (0 < P < 1), as ``apply --interval`` (:mod:`fsdecouple.evaluation.intervals`).

    Returns
    -------
    pandas.DataFrame
        A copy of ``frame`` with ``fx, fy, fz`` [load unit] (NaN where a row has no
        forces), the bounds if asked, and ``status`` (:data:`fsdecouple.logs.apply.STATUSES`).
    """
    f, code = frame_forces(model, frame, tare=tare, zero=zero, settings=settings, interval=interval)
    out = frame.copy()
    names = model.layout.loads + (interval_names(model.layout.loads) if interval is not None else ())
    for a, name in enumerate(names):
        out[name] = f[:, a]
    out[STATUS_COLUMN] = _NAMES[code]
    return out


def frame_forces(model: CouplingErrorModel, frame: pd.DataFrame, *, tare: int | None = None,
                 zero=None, settings: Settings | None = None,
                 interval: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The arrays of :func:`decouple_frame`, for engines that build their own columns.

    Returns ``(f, code)``: forces, shape (n, N) [load unit] (with ``interval``: shape
    (n, 3N), the forces then each one's lower and upper bound), NaN where a row has
    none, and each row's status as an index into :data:`fsdecouple.logs.apply.STATUSES`.
    """
    if interval is not None:
        half_widths(model, interval)  # refused before any work
        clash = [c for c in interval_names(model.layout.loads) if c in frame.columns]
        if clash:
            raise InputError(f"the frame already has a column named '{clash[0]}', which the "
                             "interval would overwrite")
    if tare is not None and zero is not None:
        raise InputError("give either tare or zero, not both")
    settings, _ = check_options(model, settings, None, None, None)  # its units: the model's
    raw = frame_outputs(model, frame, settings)
    offsets = np.zeros(model.n_inputs)
    if tare is not None:
        offsets = tare_offsets(raw, tare)
    elif zero is not None:
        offsets = np.asarray(zero, dtype=float)
        if offsets.shape != (model.n_inputs,) or not np.isfinite(offsets).all():
            raise InputError(f"zero {zero!r}: expected {model.n_inputs} finite values "
                             f"({', '.join(input_names(model))})")
    elif model.zero is not None:  # zero: intercept: the offsets fitted with the loads
        offsets = np.asarray(model.zero, dtype=float)
    f, code, empty = decouple_rows(model, raw, offsets, RowRules.for_model(model, settings))
    if interval is not None:
        f = with_intervals(model, f, interval, model.zero_corrected(raw, offsets))
    f[empty] = np.nan
    return f, code
