"""Decouple a logged voltage file into forces, in chunks (files larger than memory).

Every input row is kept, in order, and every input column is passed through as
text, unchanged; ``fx, fy, fz`` [N] and ``status`` are appended.  ``status`` says
what the forces of the row are worth (:data:`STATUSES`); rows that cannot be
decoupled keep empty forces and are counted.  The output uses the log's CSV
dialect (``sep``, ``decimal``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .config import FORCE_COLUMNS, VOLTAGE_COLUMNS, Settings
from .errors import InputError, where
from .io import (
    HEADER_ROW,
    atomic_write,
    csv_chunks,
    read_header,
    refuse_overwriting_input,
    require_columns,
)
from .model import CouplingErrorModel
from .zero import tare_offsets

CHUNK_ROWS = 200_000
RANGE_MARGIN = 0.01  # fraction of the calibrated voltage span
MISSING = ("", "nan", "NaN", "NA", "N/A", "null")
STATUS_COLUMN = "status"
# What a row's forces are worth.  Only "ok" and "extrapolated" rows have forces.
STATUSES = {
    "ok": "decoupled by eq. (11), voltages inside the calibrated range",
    "extrapolated": "decoupled, but a voltage lies outside the calibrated range",
    "missing": "a voltage is empty or missing (blank or short row): no forces",
    "truncated": "last line of a log that does not end with a newline (the writer "
                 "was cut off, a number may be cut short): no forces",
    "not_finite": "the voltages are so large that eq. (11) overflows: no forces",
}
STATUS_NAMES = np.array(list(STATUSES), dtype=object)
OK_, EXTRAPOLATED_, MISSING_, TRUNCATED_, NOT_FINITE_ = range(len(STATUSES))


@dataclass
class ApplySummary:
    """What ``apply`` did: rows written, per-status counts, the zero removed [V]."""

    rows: int = 0
    missing_rows: int = 0
    first_missing: list[int] = field(default_factory=list)
    out_of_range_rows: int = 0
    truncated_rows: int = 0
    not_finite_rows: int = 0
    status_counts: dict[str, int] = field(default_factory=lambda: dict.fromkeys(STATUSES, 0))
    offsets: np.ndarray = field(default_factory=lambda: np.zeros(3))


def _voltages(chunk: pd.DataFrame, names: list[str], settings: Settings, path, first_row: int):
    """Voltages [V] of a chunk of strings; missing cells become NaN, junk is an error."""
    u = np.empty((len(chunk), 3))
    for k, name in enumerate(names):
        text = chunk[name].str.strip()
        if settings.decimal != ".":
            text = text.str.replace(settings.decimal, ".", regex=False)
        vals = pd.to_numeric(text, errors="coerce").to_numpy(dtype=float)
        bad = np.isnan(vals) & ~text.isin(MISSING).to_numpy()
        bad |= np.isinf(vals)
        if bad.any():
            i = int(np.argmax(bad))
            raise InputError(
                f"{where(path, first_row + i, name)}: {chunk[name].iloc[i]!r}, expected a number"
            )
        u[:, k] = vals * settings.scale[VOLTAGE_COLUMNS[k]]
    return u


def _read_chunks(path: Path, settings: Settings, chunk_rows: int, nrows=None, handle=None):
    for chunk in csv_chunks(
        handle if handle is not None else path, path, settings, chunksize=chunk_rows, nrows=nrows
    ):
        chunk.columns = [str(c).strip() for c in chunk.columns]
        yield chunk


def _with_last(chunks):
    """Yield (chunk, is_last): the last chunk is known only once the next read fails."""
    prev = None
    for chunk in chunks:
        if prev is not None:
            yield prev, False
        prev = chunk
    if prev is not None:
        yield prev, True


def ends_with_newline(path: Path) -> bool:
    with open(path, "rb") as fh:
        fh.seek(0, 2)
        if fh.tell() == 0:
            return True
        fh.seek(-1, 2)
        return fh.read(1) in (b"\n", b"\r")


def apply_file(
    model: CouplingErrorModel,
    voltages: str | Path,
    out: str | Path,
    *,
    settings: Settings | None = None,
    tare: int | None = None,
    zero: tuple[float, float, float] | None = None,
    force: bool = False,
    chunk_rows: int = CHUNK_ROWS,
    progress: Callable[[int, int], None] | None = None,
) -> ApplySummary:
    """Decouple the voltage log ``voltages`` into ``out`` by eq. (11).

    Parameters
    ----------
    settings : Settings, optional
        Column names, scales and CSV dialect of the log; default: the model's.
    tare : int, optional
        Subtract the mean voltages of the first ``tare`` rows (task-data zero).
    zero : (float, float, float), optional
        Subtract these voltages [V] instead.
    progress : callable, optional
        Called as ``progress(bytes_done, bytes_total)``.
    """
    path = Path(voltages)
    settings = settings or model.settings
    if tare is not None and zero is not None:
        raise InputError("give either --tare or --zero, not both")
    header = read_header(path, settings)
    refuse_overwriting_input(out, [path])
    names = [settings.columns[c] for c in VOLTAGE_COLUMNS]
    require_columns(header, dict(zip(VOLTAGE_COLUMNS, names, strict=True)), path)
    clash = [c for c in (*FORCE_COLUMNS, STATUS_COLUMN) if c in header]
    if clash:
        raise InputError(
            f"{where(path, HEADER_ROW, clash[0])}: the log already has a column named "
            f"'{clash[0]}', which the output would overwrite"
        )
    summary = ApplySummary()
    if tare is not None:
        head = pd.concat(list(_read_chunks(path, settings, chunk_rows, nrows=tare)))
        summary.offsets = tare_offsets(
            _voltages(head, names, settings, path, HEADER_ROW + 1), tare, source=path
        )
    elif zero is not None:
        summary.offsets = np.asarray(zero, dtype=float)
    lo, hi = model.calibrated_range.T
    # Noise around an end of the range (e.g. Z's 0 N end at rest) is not
    # extrapolation worth a warning: allow 1 % of the calibrated span.
    margin = RANGE_MARGIN * (hi - lo)
    lo, hi = lo - margin, hi + margin
    total = max(1, path.stat().st_size)
    cut_short = not ends_with_newline(path)
    with atomic_write(out, force=force) as fh, open(path, "rb") as raw:
        first_row = HEADER_ROW + 1
        for chunk, last in _with_last(_read_chunks(path, settings, chunk_rows, handle=raw)):
            u = _voltages(chunk, names, settings, path, first_row) - summary.offsets
            code = np.zeros(len(chunk), dtype=np.int8)  # index into STATUS_NAMES
            missing = np.isnan(u).any(axis=1)
            code[missing] = MISSING_
            if last and cut_short and len(chunk):
                # a writer that crashed mid-line: the fields may be complete but
                # the last number cut short, so the row gets no forces
                missing[-1] = True
                code[-1] = TRUNCATED_
            with np.errstate(over="ignore", invalid="ignore"):
                f = model.decouple(np.where(missing[:, None], 0.0, u))
            huge = ~missing & ~np.isfinite(f).all(axis=1)
            code[huge] = NOT_FINITE_
            f[missing | huge] = np.nan
            outside = (code == OK_) & ((u < lo) | (u > hi)).any(axis=1)
            code[outside] = EXTRAPOLATED_
            counts = np.bincount(code, minlength=len(STATUS_NAMES))
            for name, n in zip(STATUS_NAMES, counts, strict=True):
                summary.status_counts[name] += int(n)
            summary.missing_rows += int(counts[MISSING_])
            summary.truncated_rows += int(counts[TRUNCATED_])
            summary.not_finite_rows += int(counts[NOT_FINITE_])
            summary.out_of_range_rows += int(counts[EXTRAPOLATED_])
            room = 10 - len(summary.first_missing)
            if counts[MISSING_] and room > 0:
                summary.first_missing += [
                    int(r) for r in np.flatnonzero(code == MISSING_)[:room] + first_row
                ]
            for k, c in enumerate(FORCE_COLUMNS):
                chunk[c] = f[:, k]
            chunk[STATUS_COLUMN] = STATUS_NAMES[code]
            chunk.to_csv(
                fh, index=False, header=summary.rows == 0, sep=settings.sep,
                decimal=settings.decimal, lineterminator="\n",
            )
            summary.rows += len(chunk)
            first_row += len(chunk)
            if progress is not None:
                progress(min(total, raw.tell()), total)
        if summary.rows == 0:
            raise InputError(f"{path}: header only, no data rows")
    return summary
