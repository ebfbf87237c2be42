"""A log that looks unzeroed: most rows outside the calibrated range by about one offset.

A load cell's raw zero is hundreds of thousands of counts (750,112 on
``sample_data/loadcell``), while its calibration spans the zero-corrected outputs
(+-10,000 counts about zero): a log applied without a tare or a zero decodes zero load
to hundreds of gram-force and marks every row 'extrapolated'.  ``apply`` keeps the median
of each output over each block; when no tare or zero was given, most rows are
extrapolated and an output's median over the log lies outside its calibrated range,
the log is taken as unzeroed and the warning says so.
"""

from __future__ import annotations

import warnings

import numpy as np

# rows a block's median is taken over: a longer block's evenly spaced rows
MEDIAN_ROWS = 1 << 14


def block_median(u: np.ndarray, scale: np.ndarray | float = 1.0) -> np.ndarray:
    """The median of each output over a block's rows ``u * scale`` (NaN for an all-empty
    column), over at most MEDIAN_ROWS evenly spaced rows.

    The warning looks for an offset of about the calibrated span, which 16,384 rows
    place to a small fraction of the outputs' spread; every row of apply's 131,072-row
    blocks cost 0.4 s of CPU on a 10 M-row log (a tenth of apply's).
    """
    step = -(-len(u) // MEDIAN_ROWS)  # ceil: 1 for a short block, which is taken whole
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an all-empty column
        return np.nanmedian(u[::max(step, 1)] * scale, axis=0)


def untared(summary, medians: list[np.ndarray], rules) -> tuple[str, float, float, float] | None:
    """``(output, median, lo, hi)``: the output farthest outside its calibrated range lo..hi
    (relative to its span) by its median over the log, for a log that looks unzeroed;
    None otherwise.  ``summary``: the log's :class:`~fsdecouple.logs.apply.ApplySummary`;
    ``medians``: each block's :func:`block_median` (none when a tare or zero was given);
    ``rules``: the :class:`~fsdecouple.logs.apply.RowRules` (None: M > N, whose calibrated
    range is the projection's, not the outputs')."""
    if rules is None or not medians or 2 * summary.out_of_range_rows <= summary.rows:
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        median = np.nanmedian(np.vstack(medians), axis=0)
    lo, hi = rules.lo, rules.hi
    with np.errstate(invalid="ignore", divide="ignore"):
        beyond = np.maximum(lo - median, median - hi) / (hi - lo)
    beyond = np.where(np.isfinite(beyond), beyond, -np.inf)
    if not (beyond > 0).any():
        return None
    c = int(np.argmax(beyond))
    return summary.outputs[c], float(median[c]), float(lo[c]), float(hi[c])
