"""Reading and writing files: calibration CSVs, voltage logs, atomic writes.

Every reader turns a problem into an :class:`~fsdecouple.errors.InputError` that
names the file, the row (header = row 1, as a spreadsheet counts) and the column.
"""

from __future__ import annotations

import contextlib
import csv
import difflib
import errno
import hashlib
import os
import re
import tempfile
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .config import FORCE_COLUMNS, VOLTAGE_COLUMNS, Settings
from .errors import InputError, where

if TYPE_CHECKING:  # pandas loads on first use: apply and show never need it
    import pandas as pd

HEADER_ROW = 1  # data row i (0-based) is spreadsheet row i + 2


def sha256_file(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def natural_key(name: str) -> list:
    """Sort ``rep2`` before ``rep10``."""
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]


MAX_HEADER_CHARS = 1 << 20


def read_header(path: Path, settings: Settings) -> list[str]:
    """The header row as written, refusing empty files and duplicated names."""
    try:
        with open(path, encoding="utf-8-sig", newline="") as fh:
            first = fh.readline(MAX_HEADER_CHARS)  # any line end: \n, \r\n or \r
            more = bool(fh.read(1))
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a directory, expected a CSV file") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a UTF-8 text file") from None
    except OSError as err:
        raise InputError(f"{path}: cannot read ({err.strerror})") from None
    if first.endswith("\r") and not first.endswith("\r\n"):
        raise InputError(
            f"{where(path, HEADER_ROW)}: lines end with a carriage return only (old Mac line "
            "ends); convert them to \\n or \\r\\n"
        )
    if more and not first.endswith("\n"):
        raise InputError(f"{where(path, HEADER_ROW)}: no line end in {MAX_HEADER_CHARS:,} "
                         "characters; not a CSV file?")
    if not first.strip():
        if path.stat().st_size > len(first.encode("utf-8")):
            raise InputError(f"{where(path, HEADER_ROW)}: blank, expected the header row")
        raise InputError(f"{path}: file is empty (no header row)")
    names = [n.strip() for n in next(csv.reader([first], delimiter=settings.sep))]
    seen: set[str] = set()
    for i, n in enumerate(names):
        if n in seen:
            raise InputError(f"{where(path, HEADER_ROW, n)}: duplicated column name")
        seen.add(n)
        if not n:
            raise InputError(f"{where(path, HEADER_ROW)}: column {i + 1} has no name")
    if settings.sep != ";" and any(";" in n for n in names):
        raise InputError(
            f"{where(path, HEADER_ROW)}: looks like a ';'-separated CSV; set "
            "csv: {sep: ';', decimal: ','} in the config to read it"
        )
    return names


def _strict(read):
    # only around pandas' own work, not across a generator's yields
    import pandas as pd

    with warnings.catch_warnings():
        warnings.simplefilter("error", pd.errors.ParserWarning)
        return read()


def csv_chunks(source, path: Path, settings: Settings, **kw):
    """``pandas.read_csv`` of strings that never guesses, as an iterator of frames.

    Blank lines are kept (row numbers stay true) and the first column is never
    taken as an index: pandas does that silently when the first data row has one
    field more than the header, which is how ``1,5`` in a comma file looks.
    """
    import pandas as pd

    try:
        reader = _strict(lambda: pd.read_csv(
            source, sep=settings.sep, dtype=str, keep_default_na=False, na_filter=False,
            skip_blank_lines=False, encoding="utf-8-sig", index_col=False, **kw,
        ))
        if isinstance(reader, pd.DataFrame):
            yield reader
            return
        with reader:
            while (chunk := _strict(lambda: next(reader, None))) is not None:
                yield chunk
    except pd.errors.EmptyDataError:
        raise InputError(f"{path}: file is empty (no header row)") from None
    except pd.errors.ParserWarning:
        raise InputError(
            f"{where(path, HEADER_ROW + 1)}: more fields than the header's "
            f"(a decimal comma in a '{settings.sep}'-separated file?)"
        ) from None
    except pd.errors.ParserError as err:
        raise InputError(f"{path}: {parser_message(err)}") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a UTF-8 text file") from None


def read_csv_text(path: Path, settings: Settings, **kw) -> pd.DataFrame:
    """Read a whole CSV as strings, blank lines kept so that row numbers stay true."""
    df = next(csv_chunks(path, path, settings, skipinitialspace=True, **kw))
    df.columns = [str(c).strip() for c in df.columns]
    return df


def parser_message(err: Exception) -> str:
    text = str(err)
    m = re.search(r"Expected (\d+) fields in line (\d+), saw (\d+)", text)
    if m:
        return (
            f"row {m.group(2)}: {m.group(3)} fields, expected {m.group(1)} as in the header "
            "(a decimal comma, or a separator inside a value?)"
        )
    m = re.search(r"EOF inside string starting at row (\d+)", text)
    if m:  # pandas counts lines from 0 here
        return f"row {int(m.group(1)) + 1}: a quote (\") opens a value that never closes"
    return f"cannot parse CSV ({text.strip().splitlines()[-1]})"


# Cells of a log that mean "no sample" (a missing voltage, not an error): these
# spellings in any case, with or without a sign (pyarrow reads "NAN" and "-nan"
# as NaN, so the line-by-line reader must agree).  MISSING_CELLS are the exact
# spellings pyarrow is told are null.
MISSING_WORDS = frozenset({"", "nan", "na", "n/a", "null"})
MISSING_CELLS = ("", "nan", "NaN", "NA", "N/A", "null")


def to_numbers(
    values, path: Path, column: str, rows, decimal: str = ".", *, allow_missing: bool = False
) -> np.ndarray:
    """Convert a column of strings to finite floats, or name the first bad cell.

    ``rows``: the spreadsheet row of each value, or (an int) of the first value
    when the rows are consecutive.  ``allow_missing``: empty cells and the words
    of :data:`MISSING_WORDS` become NaN (a log's missing samples) instead of an
    error (a calibration point must have every number).  Infinities are errors.
    """
    import pandas as pd

    values = pd.Series(values, dtype=object) if not isinstance(values, pd.Series) else values
    text = values.astype(str).str.strip()
    if decimal != ".":
        text = text.str.replace(decimal, ".", regex=False)
    nums = pd.to_numeric(text, errors="coerce").to_numpy(dtype=float)
    bad = ~np.isfinite(nums)
    if allow_missing and bad.any():
        missing = text.str.lower().str.lstrip("+-").isin(MISSING_WORDS).to_numpy()
        bad &= ~(np.isnan(nums) & missing)
    if bad.any():
        i = int(np.argmax(bad))
        row = int(rows[i]) if np.ndim(rows) else int(rows) + i
        cell = str(values.iloc[i]).strip()
        what = "is empty" if cell == "" else f"is {cell!r}"
        raise InputError(f"{where(path, row, column)}: {what}, expected a finite number")
    return nums


def refuse_overwriting_input(out: str | Path, inputs) -> None:
    """Refuse an output path that is one of the inputs, even with ``--force``."""
    target = Path(out).resolve()
    for f in inputs:
        if Path(f).resolve() == target:
            raise InputError(f"{out}: is also an input file; write the output somewhere else")


def require_columns(header: list[str], wanted: dict[str, str], path: Path) -> None:
    for canonical, name in wanted.items():
        if name not in header:
            hint = f" (config maps '{canonical}' to it)" if name != canonical else ""
            lower = {h.lower(): h for h in header}
            close = [lower[m] for m in difflib.get_close_matches(name.lower(), list(lower), n=1)]
            mean = f" (did you mean '{close[0]}'? map it under columns: in the config)" if close else ""
            raise InputError(
                f"{where(path, HEADER_ROW)}: missing column '{name}'{hint}{mean}; "
                f"found {', '.join(header) or 'no columns'}"
            )


# --- calibration data -------------------------------------------------------

def calibration_files(path: str | Path) -> list[Path]:
    """The CSV files of a calibration set: a directory (sorted naturally) or one file."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: calibration data not found")
    if path.is_dir():
        files = sorted(
            (p for p in path.iterdir()
             if p.suffix.lower() == ".csv" and p.is_file() and not p.name.startswith(".")),
            key=lambda p: natural_key(p.name),
        )
        if not files:
            raise InputError(f"{path}: directory holds no .csv files")
        return files
    return [path]


def hidden_files(path: str | Path) -> list[Path]:
    """Hidden .csv files a directory holds (macOS ``._rep1.csv``, editor backups)."""
    path = Path(path)
    if not path.is_dir():
        return []
    return sorted(p for p in path.iterdir() if p.name.startswith(".") and p.suffix.lower() == ".csv")


def read_calibration_table(path: str | Path, settings: Settings) -> tuple[pd.DataFrame, list[str]]:
    """Read a calibration set into one long table in file order.

    Returns the table (columns ``repetition, axis, file, row, fx..uz`` with forces
    in N and voltages in V after the config's ``scale``; ``axis`` is empty when the
    files have no axis column) and the list of skipped blank rows.
    """
    import pandas as pd

    files = calibration_files(path)
    single = len(files) == 1 and not Path(path).is_dir()
    frames, skipped = [], []
    cols = settings.columns
    numeric = {c: cols[c] for c in (*FORCE_COLUMNS, *VOLTAGE_COLUMNS)}
    for rep_index, f in enumerate(files, start=1):
        header = read_header(f, settings)
        if {"ux_raw", "uy_raw", "uz_raw"} <= set(header):
            # the tidy CSV of `ingest -o`: zero-corrected already, and every repetition
            raise InputError(
                f"{where(f, HEADER_ROW)}: this is the output of 'fsdecouple ingest -o' (it has "
                "ux_raw), not a repetition; move it out of the calibration directory"
            )
        require_columns(header, numeric, f)
        if single:
            require_columns(header, {"repetition": cols["repetition"]}, f)
        raw = read_csv_text(f, settings)
        if raw.empty:
            raise InputError(f"{f}: header only, no data rows")
        rows = np.arange(len(raw)) + HEADER_ROW + 1
        used = [cols[c] for c in numeric] + (
            [cols["axis"]] if cols["axis"] in header else []
        ) + ([cols["repetition"]] if single else [])
        blank = np.logical_and.reduce([raw[c].str.strip().eq("").to_numpy() for c in used])
        for r in rows[blank]:
            skipped.append(f"{f}, row {r}: blank row skipped")
        raw, rows = raw[~blank], rows[~blank]
        if raw.empty:
            raise InputError(f"{f}: header only, no data rows")
        out = pd.DataFrame({"file": str(f), "row": rows})
        if single:
            reps = to_numbers(raw[cols["repetition"]], f, cols["repetition"], rows)
            bad = (reps != np.round(reps)) | (reps < 1)
            if bad.any():
                i = int(np.argmax(bad))
                raise InputError(
                    f"{where(f, int(rows[i]), cols['repetition'])}: "
                    f"{raw[cols['repetition']].iloc[i]!r} is not a repetition number (1, 2, ...)"
                )
            out["repetition"] = reps.astype(int)
        else:
            out["repetition"] = rep_index
        if cols["axis"] in header:
            axis = raw[cols["axis"]].str.strip().str.lower()
            bad = ~axis.isin(["x", "y", "z"])
            if bad.any():
                i = int(np.argmax(bad.to_numpy()))
                raise InputError(
                    f"{where(f, int(rows[i]), cols['axis'])}: "
                    f"{raw[cols['axis']].iloc[i]!r}, expected x, y or z"
                )
            out["axis"] = axis.to_numpy()
        else:
            out["axis"] = ""
        for canonical, name in numeric.items():
            values = to_numbers(raw[name], f, name, rows, settings.decimal)
            # check each cell before scaling so the message quotes the file's value
            out[canonical] = values * settings.scale[canonical]
        frames.append(out)
    table = pd.concat(frames, ignore_index=True)
    # training order is file order: repetition, then row (stable)
    table = table.sort_values(["repetition"], kind="stable").reset_index(drop=True)
    return table[["repetition", "axis", "file", "row", *FORCE_COLUMNS, *VOLTAGE_COLUMNS]], skipped


# --- atomic output ------------------------------------------------------------

# errors of a write that a user can act on (free space, permissions): not bugs
_WRITE_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EACCES, errno.EPERM}


def check_output(path: str | Path, *, force: bool) -> None:
    """Refuse, before any work is done, an output that cannot or may not be written."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path}: is a directory, expected a file name for the output")
    if not force and path.exists():
        raise InputError(f"{path}: already exists; pass --force to overwrite it")
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise InputError(f"{path}: directory {directory} does not exist")


@contextlib.contextmanager
def atomic_write(path: str | Path, mode: str = "w", *, force: bool = True) -> Iterator:
    """Write to a temporary file beside ``path`` and rename it into place on success.

    The temporary file is hidden (``.NAME.XXXX.tmp``) in the same directory, so the
    rename is atomic.  An exception, Ctrl-C or SIGTERM leaves any previous file
    untouched and removes the temporary file; a full disk is reported as an
    :class:`InputError`.  Only SIGKILL (or a power cut) can leave the hidden
    temporary file behind, never a partial ``path``.
    """
    path = Path(path)
    check_output(path, force=force)
    directory = path.parent if str(path.parent) else Path(".")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=directory)
    except OSError as err:
        raise InputError(f"{path}: cannot write in {directory} ({err.strerror})") from None
    try:
        # mkstemp creates the file 0600; give the output the mode a plain open() would
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        with os.fdopen(fd, mode, **({} if "b" in mode else {"encoding": "utf-8", "newline": ""})) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as err:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(err, OSError) and err.errno in _WRITE_ERRNOS:
            raise InputError(
                f"{path}: cannot write ({err.strerror}); any previous file is unchanged"
            ) from None
        raise


# --- task logs with true forces (combined-load validation) --------------------

def read_task_log(
    voltages: str | Path, forces: str | Path, settings: Settings
) -> tuple[np.ndarray, np.ndarray]:
    """A voltage log and its true forces, as ``simulate`` writes them, row for row.

    Returns ``(u, f)``, shape (n, 3) each, in V and N (config columns and scales).
    """
    out = []
    for path, canon in ((Path(voltages), VOLTAGE_COLUMNS), (Path(forces), FORCE_COLUMNS)):
        header = read_header(path, settings)
        names = {c: settings.columns[c] for c in canon}
        require_columns(header, names, path)
        raw = read_csv_text(path, settings)
        if raw.empty:
            raise InputError(f"{path}: header only, no data rows")
        out.append(np.column_stack([
            to_numbers(raw[n], path, n, HEADER_ROW + 1, settings.decimal) * settings.scale[c]
            for c, n in names.items()
        ]))
    u, f = out
    if len(u) != len(f):
        raise InputError(
            f"{forces}: {len(f)} rows, but {voltages} has {len(u)}; the true forces must "
            "match the voltage log row for row"
        )
    return u, f
