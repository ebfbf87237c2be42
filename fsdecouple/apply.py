"""Decouple a logged voltage file into forces, in chunks (files larger than memory).

Every input column is passed through as text, unchanged and in order; ``fx, fy,
fz`` [N] are appended.  Rows with a missing voltage are kept with empty forces
and counted.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .config import FORCE_COLUMNS, VOLTAGE_COLUMNS, Settings
from .errors import InputError, where
from .io import HEADER_ROW, atomic_write, parser_message, read_header, require_columns
from .model import CouplingErrorModel
from .zero import tare_offsets

CHUNK_ROWS = 200_000
RANGE_MARGIN = 0.01  # fraction of the calibrated voltage span
MISSING = ("", "nan", "NaN", "NA", "N/A", "null")


@dataclass
class ApplySummary:
    rows: int = 0
    missing_rows: int = 0
    first_missing: list[int] = field(default_factory=list)
    out_of_range_rows: int = 0
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
    try:
        yield from pd.read_csv(
            handle if handle is not None else path, sep=settings.sep, dtype=str,
            keep_default_na=False, na_filter=False, encoding="utf-8-sig",
            chunksize=chunk_rows, nrows=nrows,
        )
    except pd.errors.EmptyDataError:
        raise InputError(f"{path}: file is empty (no header row)") from None
    except pd.errors.ParserError as err:
        raise InputError(f"{path}: {parser_message(err)}") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a UTF-8 text file") from None


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
    names = [settings.columns[c] for c in VOLTAGE_COLUMNS]
    require_columns(header, dict(zip(VOLTAGE_COLUMNS, names, strict=True)), path)
    clash = [c for c in FORCE_COLUMNS if c in header]
    if clash:
        raise InputError(
            f"{where(path, HEADER_ROW, clash[0])}: the log already has a column named "
            f"'{clash[0]}', which the output would overwrite"
        )
    summary = ApplySummary()
    if tare is not None:
        head = pd.concat(list(_read_chunks(path, settings, chunk_rows, nrows=tare)))
        summary.offsets = tare_offsets(
            _voltages(head, names, settings, path, HEADER_ROW + 1), tare
        )
    elif zero is not None:
        summary.offsets = np.asarray(zero, dtype=float)
    lo, hi = model.calibrated_range.T
    # Noise around an end of the range (e.g. Z's 0 N end at rest) is not
    # extrapolation worth a warning: allow 1 % of the calibrated span.
    margin = RANGE_MARGIN * (hi - lo)
    lo, hi = lo - margin, hi + margin
    total = max(1, path.stat().st_size)
    with atomic_write(out, force=force) as fh, open(path, "rb") as raw:
        first_row = HEADER_ROW + 1
        wrote_header = False
        for chunk in _read_chunks(path, settings, chunk_rows, handle=raw):
            u = _voltages(chunk, names, settings, path, first_row) - summary.offsets
            missing = np.isnan(u).any(axis=1)
            f = model.decouple(u)
            f[missing] = np.nan
            n_missing = int(missing.sum())
            if n_missing:
                summary.missing_rows += n_missing
                room = 10 - len(summary.first_missing)
                summary.first_missing += [int(r) for r in np.flatnonzero(missing)[:room] + first_row]
            ok = ~missing
            summary.out_of_range_rows += int(((u[ok] < lo) | (u[ok] > hi)).any(axis=1).sum())
            for k, c in enumerate(FORCE_COLUMNS):
                chunk[c] = f[:, k]
            chunk.to_csv(fh, index=False, header=not wrote_header, lineterminator="\n")
            wrote_header = True
            summary.rows += len(chunk)
            first_row += len(chunk)
            if progress is not None:
                progress(min(total, raw.tell()), total)
        if not wrote_header:
            raise InputError(f"{path}: header only, no data rows")
    return summary
