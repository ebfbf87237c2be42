"""Text tables: the header row, pandas reads that never guess, numbers from cells.

Every reader turns a problem into an :class:`~fsdecouple.errors.InputError` that
names the file, the row (header = row 1, as a spreadsheet counts) and the column.
"""

from __future__ import annotations

import csv
import difflib
import functools
import io
import itertools
import os
import re
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..config import Settings
from ..errors import InputError, excerpt, printable, where
from ..files.inputs import CALIBRATION_LIMIT, non_utf8_cell, non_utf8_message, read_bounded, reading

if TYPE_CHECKING:  # pandas loads on first use: apply and show never need it
    import pandas as pd

HEADER_ROW = 1  # data row i (0-based) is spreadsheet row i + 2

MAX_HEADER_CHARS = 1 << 20


def read_header(path: Path, settings: Settings, data: bytes | None = None, *,
                strict: bool = True, more: bool | None = None) -> list[str]:
    """The header row as written (names stripped), refusing empty files.

    ``data``: the file's bytes when the caller has read them already (a file is
    read once per command).  ``strict``: refuse duplicated and empty names too
    (a log passes every column through); otherwise only the columns the config
    maps must be unique (:func:`require_columns`), and the rest, a side table
    or columns without a name, are ignored.  ``more``: whether anything follows
    ``data`` in the file (then ``data`` is the first line only: the header must be
    UTF-8, the rows after it are not decoded here).
    """
    with reading(path):
        if data is None:
            with open(path, encoding="utf-8-sig", newline="") as fh:
                first = fh.readline(MAX_HEADER_CHARS)  # any line end: \n, \r\n or \r
                more = bool(fh.read(1))
                size = os.fstat(fh.fileno()).st_size
        else:
            fh = io.TextIOWrapper(io.BytesIO(data), encoding="utf-8-sig", newline="")
            first = fh.readline(MAX_HEADER_CHARS)
            size = len(data) + bool(more)
            more = bool(fh.read(1)) or bool(more)
    if first.endswith("\r") and not first.endswith("\r\n"):
        raise InputError(
            f"{where(path, HEADER_ROW)}: lines end with a carriage return only (old Mac line "
            "ends); convert them to \\n or \\r\\n"
        )
    if more and not first.endswith("\n"):
        raise InputError(f"{where(path, HEADER_ROW)}: no line end in {MAX_HEADER_CHARS:,} "
                         "characters; not a CSV file?")
    if not first.strip():
        if size > len(first.encode("utf-8")):
            raise InputError(f"{where(path, HEADER_ROW)}: blank, expected the header row")
        raise InputError(f"{path}: file is empty (no header row)")
    names = [n.strip() for n in next(csv.reader([first], delimiter=settings.sep))]
    seen: set[str] = set()
    for i, n in enumerate(names if strict else ()):
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
        said = non_utf8_message(str(path), source, settings.sep)
        if said:  # a spreadsheet's Latin-1 export: which cell
            raise InputError(said) from None
        raise InputError(f"{path}: not a UTF-8 text file") from None


def read_csv_text(source, settings: Settings, *, path: Path | None = None, **kw) -> pd.DataFrame:
    """Read a whole CSV (a path, or a buffer read from ``path``) as strings.

    Blank lines are kept so that row numbers stay true.
    """
    path = Path(source) if path is None else path
    df = next(csv_chunks(source, path, settings, skipinitialspace=True, **kw))
    df.columns = [str(c).strip() for c in df.columns]
    return df


# A line that pandas' C tokenizer reads as plainly as a split on the separator would:
# every field unquoted (no quote character) or wholly quoted, a quote opening it after any
# spaces and closing it right before the separator or the line's end.  Mid-field quotes,
# text after a closing quote and values running over lines are left to pandas.
@functools.cache
def _plain_line(sep: str) -> re.Pattern:
    s = re.escape(sep)
    field = f'(?: *"(?:[^"]|"")*"|[^"{s}]*)'
    return re.compile(f"{field}(?:{s}{field})*")


def read_cells(data: bytes, settings: Settings, path: Path, width: int) -> tuple[np.ndarray, bool]:
    """The data rows of a whole CSV's bytes as cells: ``(cells, spaced)``.

    ``cells``, an object array of shape (rows, ``width``) of ``str``, holds exactly what
    :func:`read_csv_text` (``header=0``, one positional name per header field) reads: a
    blank line is a row of empty cells, a short row is padded with empty cells, spaces
    after a separator are skipped, and every refusal is the same.  Plain files (UTF-8,
    ``\n`` or ``\r\n`` line ends, quotes only around whole fields, no row wider than the
    header) are split here, at a fraction of pandas' cost (a calibration set is read by
    every fit, cv and test); anything else is read by pandas itself.  ``spaced``: whether
    a cell may begin or end with white space (False: ``str.strip`` would change none).
    """
    split = _split_plain(data, settings.sep, width)
    if split is not None:
        return split
    raw = read_csv_text(io.BytesIO(data), settings, path=path, header=0,
                        names=[str(i) for i in range(width)])
    return raw.to_numpy(dtype=object).reshape(len(raw), width), True


def _split_plain(data: bytes, sep: str, width: int) -> tuple[np.ndarray, bool] | None:
    """:func:`read_cells` of a plain file, or None to leave the file to pandas."""
    if len(sep) != 1 or sep in ' "\r\n':
        return None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        return None
    if "\r" in text:
        text = text.replace("\r\n", "\n")
        if "\r" in text:  # a line ending in \r alone (old Mac) or a \r inside a value
            return None
    if text.startswith("\ufeff"):  # a second byte-order mark, which pandas skips too
        return None
    lines = text.split("\n")
    if lines[-1] == "":
        lines.pop()  # the last line's end
    if not lines:
        return None
    header, lines = lines[0], lines[1:]
    if '"' in header or len(header.split(sep)) != width:
        return None
    rows = [line.split(sep) for line in lines]
    if '"' in text or " " in text:
        plain = _plain_line(sep)
        for i, line in enumerate(lines):
            if '"' in line:
                if not plain.fullmatch(line):
                    return None
                rows[i] = next(csv.reader([line], delimiter=sep, skipinitialspace=True))
            elif " " in line:  # skipinitialspace: spaces (only) after a separator are skipped
                rows[i] = [c.lstrip(" ") for c in rows[i]]
    lengths = set(map(len, rows))
    if lengths - {width}:
        if max(lengths) > width:  # pandas refuses it, in its own words
            return None
        for row in rows:
            row += [""] * (width - len(row))
    cells = np.fromiter(itertools.chain.from_iterable(rows), dtype=object,
                        count=len(rows) * width)
    return cells.reshape(len(rows), width), _spaced(text)


def _spaced(text: str) -> bool:
    """Whether ``text`` holds white space but for line ends (a cell could need stripping)."""
    if text.isascii():
        return any(c in text for c in " \t\x0b\x0c\x1c\x1d\x1e\x1f")
    return any(c.isspace() for c in set(text) - {"\n"})


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
    values, path: Path, column: str, rows, decimal: str = ".", *, allow_missing: bool = False,
    stripped: bool = False,
) -> np.ndarray:
    """Convert a column of strings to finite floats, or name the first bad cell.

    ``rows``: the spreadsheet row of each value, or (an int) of the first value
    when the rows are consecutive.  ``allow_missing``: empty cells and the words
    of :data:`MISSING_WORDS` become NaN (a log's missing samples) instead of an
    error (a calibration point must have every number).  Infinities are errors.
    ``values`` may be an object array of ``str`` (:func:`read_cells`' cells), read
    without a pandas Series; ``stripped``: its cells are stripped already.
    """
    import pandas as pd

    if isinstance(values, np.ndarray) and values.dtype == object:  # str cells, as read
        # Python's str.strip strips what pandas' .str.strip does (every Unicode space)
        text = values if stripped else np.array([c.strip() for c in values], dtype=object)
        if decimal != ".":
            text = np.array([t.replace(decimal, ".") for t in text], dtype=object)
        cells = values
    else:
        values = pd.Series(values, dtype=object) if not isinstance(values, pd.Series) else values
        text = values.astype(str).str.strip()
        if decimal != ".":
            text = text.str.replace(decimal, ".", regex=False)
        cells = values.array
    if isinstance(text, np.ndarray):
        # each distinct cell parsed once (a pose log's loads are one cell a thousand times):
        # to_numeric's value of a cell depends on the kinds of cells beside it (all whole
        # numbers or not), which the distinct cells share with the column
        codes, distinct = pd.factorize(text)
        nums = np.asarray(pd.to_numeric(distinct, errors="coerce"), dtype=float)[codes]
    else:
        nums = np.asarray(pd.to_numeric(text, errors="coerce"), dtype=float)
    bad = ~np.isfinite(nums)
    if allow_missing and bad.any():
        words = text if isinstance(text, pd.Series) else pd.Series(text, dtype=str)
        missing = words.str.lower().str.lstrip("+-").isin(MISSING_WORDS).to_numpy()
        bad &= ~(np.isnan(nums) & missing)
    if bad.any():
        i = int(np.argmax(bad))
        row = int(rows[i]) if np.ndim(rows) else int(rows) + i
        cell = str(cells[i]).strip()
        what = "is empty" if cell == "" else f"is {excerpt(repr(cell))}"
        raise InputError(f"{where(path, row, column)}: {what}, expected a finite number")
    return nums


def require_utf8(body: bytes, path: Path, first_row: int, header: list[str], sep: str,
                 why: str) -> None:
    """Refuse ``body`` (whole lines, the first at spreadsheet row ``first_row``) unless it
    is UTF-8, naming the row, column and cell of the first byte that is not
    (:func:`~fsdecouple.files.inputs.non_utf8_cell`, the calibration reader's rule too).

    The rule for a log's bytes (docs/errors.md, "Inputs"): the header must be
    UTF-8; data lines are bytes, passed through to CSV unchanged and never decoded,
    and must be UTF-8 only where they become text (Parquet output: ``why``).  Every
    block is checked the same way, whatever its row.
    """
    said = non_utf8_cell(body, sep, header=header, first_row=first_row)
    if said is not None:
        raise InputError(f"{where(path)}, {said} is not UTF-8 text; {why}")


def require_columns(header: list[str], wanted: dict[str, str], path: Path,
                    calibration: bool = False) -> None:
    """Every column the config maps is in the header, once.  ``calibration``: the file is a
    calibration file, for which ``fsdecouple init`` guesses a config (a rig's, say)."""
    for canonical, name in wanted.items():
        if header.count(name) > 1:
            raise InputError(f"{where(path, HEADER_ROW, name)}: appears {header.count(name)} times "
                             "in the header; the config maps it, so it must be unique")
        if name not in header:
            hint = f" (config maps '{canonical}' to it)" if name != canonical else ""
            lower = {h.lower(): h for h in header}
            close = [lower[m] for m in difflib.get_close_matches(name.lower(), list(lower), n=1)]
            mean = f" (did you mean '{close[0]}'? map it under columns: in the config)" if close else ""
            unnamed = [i + 1 for i, h in enumerate(header) if not h]
            blank = f"; column {unnamed[0]} has no name" if unnamed and not close else ""
            init = (f"; 'fsdecouple init {printable(path)}' guesses a config that maps them"
                    if calibration else "")
            inner = path.parent / "calibration"  # simulate's layout: OUT/calibration/rep*.csv
            if calibration and inner.is_dir() and any(inner.glob("*.csv")):
                init = f"; the calibration is in {printable(inner)}: give that directory"
            raise InputError(
                f"{where(path, HEADER_ROW)}: missing column '{name}'{hint}{mean}; "
                f"found {', '.join(h or '(no name)' for h in header) or 'no columns'}{blank}{init}"
            )


_SEPS = (",", ";", "\t")  # what init tries on a file it has never seen


def first_difference(header: list[str], first: list[str]) -> tuple[int, str, str]:
    """Where a file's header parts from the first file's: (0-based column, what this file
    has there, what the first has; ``nothing`` past a header's end), for the one-line
    refusal of a directory whose files do not share one layout."""
    j = next((i for i, (a, b) in enumerate(zip(header, first, strict=False)) if a != b),
             min(len(header), len(first)))
    return (j, repr(header[j]) if j < len(header) else "nothing",
            repr(first[j]) if j < len(first) else "nothing")


def _sniff_sep(first_line: str) -> str:
    counts = {s: len(next(csv.reader([first_line], delimiter=s), [])) for s in _SEPS}
    return max(_SEPS, key=lambda s: (counts[s], s == ","))  # a tie is a comma file


def read_rows(path: Path, max_rows: int) -> tuple[list[str], list[list[str]], str, bool]:
    """(header names, up to ``max_rows`` rows of cells, separator, whether rows were left).

    The file is read once, within the calibration files' size limit, so a pipe, a FIFO
    (waited for as every input is) or ``/dev/zero`` is read like a file or refused.
    """
    with reading(path):
        text = read_bounded(path, CALIBRATION_LIMIT, "a calibration file").decode("utf-8-sig")
    lines = io.StringIO(text, newline="")
    reader = None
    try:
        first = text.split("\n", 1)[0]
        if not first.strip():
            raise InputError(f"{printable(path)}: no header row (the first line is empty)")
        sep = _sniff_sep(first)
        reader = csv.reader(lines, delimiter=sep)
        names = [n.strip() for n in next(reader)]
        raw_rows = list(itertools.islice(reader, max_rows + 1))
    except csv.Error as err:  # a field over the csv module's 128 KiB, a NUL byte
        row = f", row {reader.line_num}" if reader is not None else ", row 1"
        raise InputError(f"{printable(path)}{row}: not a table of numbers ({excerpt(err)})") from None
    truncated = len(raw_rows) > max_rows
    del raw_rows[max_rows:]
    return names, raw_rows, sep, truncated
