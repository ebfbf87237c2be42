"""Reading and writing files: calibration CSVs, voltage logs, atomic writes.

Every reader turns a problem into an :class:`~fsdecouple.errors.InputError` that
names the file, the row (header = row 1, as a spreadsheet counts) and the column.
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import os
import re
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pandas as pd

from .config import FORCE_COLUMNS, VOLTAGE_COLUMNS, Settings
from .errors import InputError, where

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


def read_header(path: Path, settings: Settings) -> list[str]:
    """The header row as written, refusing empty files and duplicated names."""
    try:
        with open(path, encoding="utf-8-sig", newline="") as fh:
            first = fh.readline()
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a directory, expected a CSV file") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a UTF-8 text file") from None
    if not first.strip():
        raise InputError(f"{path}: file is empty (no header row)")
    names = [n.strip() for n in next(csv.reader([first], delimiter=settings.sep))]
    seen: set[str] = set()
    for i, n in enumerate(names):
        if n in seen:
            raise InputError(f"{where(path, HEADER_ROW, n)}: duplicated column name")
        seen.add(n)
        if not n:
            raise InputError(f"{where(path, HEADER_ROW)}: column {i + 1} has no name")
    if len(names) == 1 and settings.sep == "," and ";" in names[0]:
        raise InputError(
            f"{where(path, HEADER_ROW)}: looks like a ';'-separated CSV; set "
            "csv: {sep: ';', decimal: ','} in the config to read it"
        )
    return names


def read_csv_text(path: Path, settings: Settings, **kw) -> pd.DataFrame:
    """Read a whole CSV as strings, blank lines kept so that row numbers stay true."""
    try:
        df = pd.read_csv(
            path, sep=settings.sep, dtype=str, keep_default_na=False, na_filter=False,
            skip_blank_lines=False, encoding="utf-8-sig", skipinitialspace=True, **kw,
        )
    except pd.errors.EmptyDataError:
        raise InputError(f"{path}: file is empty (no header row)") from None
    except pd.errors.ParserError as err:
        raise InputError(f"{path}: {parser_message(err)}") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a UTF-8 text file") from None
    df.columns = [str(c).strip() for c in df.columns]
    return df


def parser_message(err: Exception) -> str:
    m = re.search(r"Expected (\d+) fields in line (\d+), saw (\d+)", str(err))
    if m:
        return f"row {m.group(2)}: {m.group(3)} fields, expected {m.group(1)} as in the header"
    return f"cannot parse CSV ({str(err).strip().splitlines()[-1]})"


def to_numbers(
    values: pd.Series, path: Path, column: str, first_row: int, decimal: str
) -> np.ndarray:
    """Convert a column of strings to finite floats, or name the first bad cell."""
    text = values.astype(str).str.strip()
    if decimal != ".":
        text = text.str.replace(decimal, ".", regex=False)
    nums = pd.to_numeric(text, errors="coerce").to_numpy(dtype=float)
    bad = ~np.isfinite(nums)
    if bad.any():
        i = int(np.argmax(bad))
        cell = str(values.iloc[i]).strip()
        if cell == "":
            what = "is empty"
        elif np.isnan(nums[i]) and cell.lower() not in ("nan", "na", "n/a", "null", "none"):
            what = f"is {cell!r}"
        else:
            what = f"is {cell!r}, not a finite number"
        raise InputError(f"{where(path, first_row + i, column)}: {what}, expected a number")
    return nums


def require_columns(header: list[str], wanted: dict[str, str], path: Path) -> None:
    for canonical, name in wanted.items():
        if name not in header:
            hint = f" (config maps '{canonical}' to it)" if name != canonical else ""
            raise InputError(
                f"{where(path, HEADER_ROW)}: missing column '{name}'{hint}; "
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
            (p for p in path.iterdir() if p.suffix.lower() == ".csv" and p.is_file()),
            key=lambda p: natural_key(p.name),
        )
        if not files:
            raise InputError(f"{path}: directory holds no .csv files")
        return files
    return [path]


def read_calibration_table(path: str | Path, settings: Settings) -> tuple[pd.DataFrame, list[str]]:
    """Read a calibration set into one long table in file order.

    Returns the table (columns ``repetition, axis, file, row, fx..uz`` with forces
    in N and voltages in V after the config's ``scale``; ``axis`` is empty when the
    files have no axis column) and the list of skipped blank rows.
    """
    files = calibration_files(path)
    single = len(files) == 1 and not Path(path).is_dir()
    frames, skipped = [], []
    cols = settings.columns
    numeric = {c: cols[c] for c in (*FORCE_COLUMNS, *VOLTAGE_COLUMNS)}
    for rep_index, f in enumerate(files, start=1):
        header = read_header(f, settings)
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
        blank = (raw[used].apply(lambda s: s.str.strip()) == "").all(axis=1).to_numpy()
        for r in rows[blank]:
            skipped.append(f"{f}, row {r}: blank row skipped")
        raw, rows = raw[~blank], rows[~blank]
        if raw.empty:
            raise InputError(f"{f}: header only, no data rows")
        first = int(rows[0])
        out = pd.DataFrame({"file": str(f), "row": rows})
        if single:
            reps = to_numbers(raw[cols["repetition"]], f, cols["repetition"], first, ".")
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
            values = to_numbers(raw[name], f, name, first, settings.decimal)
            # check each cell before scaling so the message quotes the file's value
            out[canonical] = values * settings.scale[canonical]
        frames.append(out)
    table = pd.concat(frames, ignore_index=True)
    # training order is file order: repetition, then row (stable)
    table = table.sort_values(["repetition"], kind="stable").reset_index(drop=True)
    return table[["repetition", "axis", "file", "row", *FORCE_COLUMNS, *VOLTAGE_COLUMNS]], skipped


# --- atomic output ------------------------------------------------------------

@contextlib.contextmanager
def atomic_write(path: str | Path, mode: str = "w", *, force: bool = True) -> Iterator:
    """Write to a temporary file beside ``path`` and rename it into place on success.

    An exception or interruption leaves any previous file untouched and removes
    the temporary file.
    """
    path = Path(path)
    if not force and path.exists():
        raise InputError(f"{path}: already exists; pass --force to overwrite it")
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise InputError(f"{path}: directory {directory} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=directory)
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
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
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
