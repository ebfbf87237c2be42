"""Stream a voltage log in blocks, CSV or Parquet, and write it back with forces.

CSV blocks are cut from the raw bytes at line ends.  The three voltage columns
are parsed by pyarrow's CSV reader; every input line is passed through as it is
(no re-quoting, no re-formatting; only its line end becomes \n) and the forces
are appended as text by pyarrow's shortest float formatting (after rounding, see
:func:`force_decimals`), so the output costs little more than reading and
writing the file.  A block
pyarrow cannot parse, or whose rows it might not count as the file's lines (a
non-numeric cell, a short or blank row, a stray carriage return), is parsed
again line by line, which either reads it or names the file, row and column at
fault.
"""

from __future__ import annotations

import csv
import os
import stat
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pcsv

from ..config import Settings
from ..data.csv_text import HEADER_ROW, MAX_HEADER_CHARS, MISSING_CELLS, read_header, require_utf8, to_numbers
from ..errors import InputError, excerpt, printable, where
from ..files.inputs import open_input, reading
from .arrow import column_floats, numbers
from .passthrough import kept_fields, kept_lines

BLOCK_BYTES = 4 << 20  # ~100 K rows of a 4-column log; a block in flight costs ~15x this
MAX_LINE_BYTES = 16 << 20  # a log line is tens of bytes
PARQUET_SUFFIXES = (".parquet", ".pq")
NOT_UTF8_PARQUET = ("Parquet output stores text as UTF-8 (CSV output passes a line's bytes "
                    "through unchanged)")
PARQUET_BATCH_ROWS = 1 << 17  # ~15 MB of blocks in flight each
# Column chunks are read through a buffer of this size rather than whole: a file
# written as one huge row group would otherwise be held in memory column by column.
# (Pre-buffering, pyarrow's default, would double the peak memory too.)
PARQUET_READ_BUFFER = 1 << 20


def is_parquet(path: str | Path) -> bool:
    return Path(path).suffix.lower() in PARQUET_SUFFIXES


@dataclass
class Block:
    """A run of consecutive data rows of a log.

    ``lines`` holds the raw CSV lines (no line end) when the input is CSV;
    ``table`` the pass-through columns when the input is Parquet, or CSV going
    to Parquet (then as strings).
    """

    first_row: int  # spreadsheet row of the first line (header = row 1)
    u: np.ndarray  # (n, 3) voltages in file units; NaN where missing
    lines: pa.Array | None = None
    table: pa.Table | None = None
    done: int = 0  # progress: bytes (CSV) or rows (Parquet) consumed
    total: int | None = 1  # None: unknown (a pipe)
    joined: bool = False  # lines carry the line feed before them (see _lines)
    truncated: bool = False  # the last line of a log cut off mid-write

    def __len__(self) -> int:
        return self.u.shape[0]


# --- reading ------------------------------------------------------------------


@dataclass
class CsvBody:
    """Raw bytes of consecutive whole lines of a CSV log, not yet parsed."""

    body: bytes
    first_row: int
    rows: int  # lines, blank ones included: every line is a row
    done: int
    total: int | None  # bytes of the log; None for a pipe
    truncated: bool = False  # the log's last line, which has no line end


def csv_bodies(fh, path: Path, *, done: int, total: int | None, chunk_rows: int,
               block_bytes: int = BLOCK_BYTES, max_line: int = MAX_LINE_BYTES) -> Iterator[CsvBody]:
    """Cut the data lines of a CSV log into blocks of whole lines (at most ``chunk_rows``).

    ``fh`` is the open binary stream, just past the header (``done`` bytes in);
    it is read forward once.  A last line without a line end comes alone, as a
    ``truncated`` body.  A line longer than ``max_line`` bytes is an error:
    memory stays bounded whatever the file.
    """
    row = HEADER_ROW + 1  # spreadsheet row of the next data line
    carry = b""
    while True:
        data = fh.read(block_bytes)
        buf = carry + data
        if not data:
            if buf:  # the writer was cut off mid-line (or left NUL padding)
                done += len(buf)
                yield CsvBody(buf, row, 1, done, total, truncated=True)
            return
        end = buf.rfind(b"\n") + 1
        if end == 0:  # a line longer than the block: read on
            if len(buf) > max_line:
                raise InputError(
                    f"{where(path, row)}: no line end in {max_line:,} bytes; not a CSV log?"
                )
            carry = buf
            continue
        body, carry = buf[:end], buf[end:]
        while body:
            feeds = body.count(b"\n")
            if feeds > chunk_rows:
                nl = np.flatnonzero(np.frombuffer(body, np.uint8) == 10)
                cut = int(nl[chunk_rows - 1]) + 1
                piece, body, feeds = body[:cut], body[cut:], chunk_rows
            else:
                piece, body = body, b""
            done += len(piece)
            yield CsvBody(piece, row, feeds, done if total is None else min(done, total), total)
            row += feeds


class LogFile:
    """A voltage log opened once: its format, header row and line ends, then its blocks.

    A CSV log is read in one forward pass from the stream opened here, so a pipe,
    a FIFO or ``-`` (standard input) is read correctly.  A Parquet log needs a
    seekable file (its footer comes first).

    Use as a context manager; :meth:`blocks` yields the data rows in order.
    """

    def __init__(self, path: str | Path, settings: Settings):
        self.path = Path(path)
        self.settings = settings
        self.parquet = is_parquet(self.path)
        self.stdin = str(path) == "-"
        self._fh = None
        self.total: int | None = None
        if self.parquet:
            self.header, self.total = parquet_header(self.path)
            self.header_line, self.eol = b"", b"\n"
            return
        with reading(self.path):
            # a FIFO without a writer is refused after FIFO_WAIT s rather than hanging
            self._fh = sys.stdin.buffer if self.stdin else open_input(self.path)
        try:
            with reading(self.path):
                line = self._fh.readline(MAX_HEADER_CHARS)
                # only whether more follows: the next byte may be half a character
                more = bool(self._fh.peek(1)[:1]) if hasattr(self._fh, "peek") else False
                if not self.stdin and stat.S_ISREG(os.fstat(self._fh.fileno()).st_mode):
                    self.total = max(1, os.fstat(self._fh.fileno()).st_size)
            # unnamed and repeated names are dropped by passed_columns unless mapped
            self.header = read_header(self.path, settings, line, more=more, strict=False)
        except BaseException:
            self.close()
            raise
        self._done = len(line)
        self.header_line = line.removeprefix(b"\xef\xbb\xbf").rstrip(b"\r\n")
        self.eol = b"\r\n" if line.endswith(b"\r\n") else b"\n"

    def __enter__(self) -> LogFile:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self._fh is not None and not self.stdin:
            self._fh.close()
        self._fh = None

    def blocks(self, names: list[str], *, chunk_rows: int, want_table: bool,
               keep: list[int] | None = None):
        """Jobs, in file order, each returning one :class:`Block` when called.

        CSV blocks are cut here and parsed when the job runs (on a worker thread);
        Parquet blocks are decoded here.  ``want_table``: the output is Parquet;
        otherwise it is CSV, and a Parquet log's columns must be writable as text.
        ``keep``: the columns passed through
        (:func:`~fsdecouple.logs.passthrough.passed_columns`); default all.
        """
        if self.parquet:
            for b in parquet_blocks(self.path, names, self.settings, chunk_rows=chunk_rows,
                                    to_csv=not want_table, keep=keep):
                yield lambda b=b: b
            return
        parse = CsvParser(self.path, self.header, names, self.settings, self.eol, want_table,
                          keep)
        for body in csv_bodies(self._fh, self.path, done=self._done, total=self.total,
                               chunk_rows=chunk_rows):
            yield partial(parse, body)


class CsvParser:
    """Parses :class:`CsvBody` blocks; thread-safe, so blocks can be parsed in parallel.

    The common block (no blank line, every row complete and numeric) is parsed by
    pyarrow and its lines passed through without a copy.  Any other block takes
    :meth:`exact`, a line-by-line parse that keeps every line as a row (blank and
    short ones padded with separators to the header's width) or names the row at
    fault.
    """

    def __init__(self, path: Path, header: list[str], names: list[str], settings: Settings,
                 eol: bytes, want_table: bool, keep: list[int] | None = None):
        self.path, self.header, self.names, self.settings = path, header, names, settings
        self.eol = eol
        self.want_table = want_table
        width = len(header)
        # columns are read by position: a header may have unnamed or repeated names
        pos = [str(i) for i in range(width)]
        self.index = [header.index(n) for n in names]
        self.keep = list(range(width)) if keep is None else list(keep)
        self.cut = len(self.keep) < width  # lines are re-written without the dropped fields
        self.float_opts = pcsv.ConvertOptions(
            include_columns=[pos[i] for i in self.index],
            column_types={pos[i]: pa.float64() for i in self.index},
            null_values=list(MISSING_CELLS), decimal_point=settings.decimal, check_utf8=False,
        )
        # Parquet output: the columns the model reads are the numbers read (doubles, a
        # missing cell null), every other column its text
        self.float_of = {j: k for k, j in enumerate(self.index)}
        text = [i for i in self.keep if i not in self.float_of]
        self.text_opts = pcsv.ConvertOptions(
            include_columns=[pos[i] for i in text],
            column_types={pos[i]: pa.string() for i in text}, strings_can_be_null=False,
        ) if want_table else None
        # one block is parsed per thread; the blocks themselves run in parallel
        self.read_opts = pcsv.ReadOptions(column_names=pos, use_threads=False)
        self.parse_opts = pcsv.ParseOptions(delimiter=settings.sep)

    def __call__(self, chunk: CsvBody) -> Block:
        body, row = chunk.body, chunk.first_row
        if self.want_table:  # the same rule for every block, whichever path parses it
            require_utf8(body, self.path, row, self.header, self.settings.sep, NOT_UTF8_PARQUET)
        # A carriage return in an LF log could split a row for pyarrow and make up
        # for a blank line it skips; such blocks are read line by line.
        if chunk.truncated or (self.eol == b"\n" and b"\r" in body) or (self.cut and b'"' in body):
            return self.exact(chunk)
        buffer = pa.py_buffer(body)
        try:
            tab = pcsv.read_csv(buffer, read_options=self.read_opts, parse_options=self.parse_opts,
                                convert_options=self.float_opts)
        except pa.ArrowInvalid:  # short or long rows, junk, an open quote: look closer
            return self.exact(chunk)
        u = np.column_stack([column_floats(tab.column(k)) for k in range(len(self.index))])
        # pyarrow skips blank lines, but each is a row of the log: fewer rows than lines
        if u.shape[0] != chunk.rows or np.isinf(u).any():
            return self.exact(chunk)
        if self.eol == b"\n" and not self.cut:
            lines, joined = _lines(body, buffer, chunk.rows), True
        else:
            if self.eol != b"\n" and body.count(b"\r") != chunk.rows:
                # a lone CR: pyarrow's rows may not be the lines
                return self.exact(chunk)
            lines, joined = pc.split_pattern(pa.array([body], pa.binary()), self.eol).flatten(), False
            if len(lines) != chunk.rows + 1:  # mixed line ends
                return self.exact(chunk)
            lines = lines.slice(0, chunk.rows)
            if self.cut:  # every line has the header's fields (pyarrow read them) and no quote
                lines = kept_lines(lines, self.keep, self.settings.sep)
        table = None
        if self.text_opts is not None:
            text = pcsv.read_csv(buffer, read_options=self.read_opts, parse_options=self.parse_opts,
                                 convert_options=self.text_opts).columns \
                if self.text_opts.include_columns else []
            table = self._table(u, text)
        return Block(row, u, lines=lines, table=table, done=chunk.done, total=chunk.total,
                     joined=joined)

    def _table(self, u: np.ndarray, text) -> pa.Table:
        """The block's columns for Parquet output, in the log's order: the read numbers of
        the columns the model reads (``u``; NaN, a missing cell, as null), the text of
        the others (``text``, in order)."""
        cols, rest = [], iter(text)
        for j in self.keep:
            k = self.float_of.get(j)
            cols.append(next(rest) if k is None else numbers(u[:, k], np.isnan(u[:, k])))
        return pa.table(cols, names=[self.header[j] for j in self.keep])

    def exact(self, chunk: CsvBody) -> Block:
        """Parse a block line by line: slower, but every line is a row, as it is in the file."""
        row, sep = chunk.first_row, self.settings.sep
        raw = chunk.body.split(b"\n")
        if not chunk.truncated:
            raw.pop()  # after the final line feed
        width = len(self.header)
        pad = sep.encode()
        lines, cells = [], []
        for i, line in enumerate(raw):
            line = line.removesuffix(b"\r")
            if line.count(b'"') % 2 and not chunk.truncated:
                raise InputError(
                    f"{where(self.path, row + i)}: a quote (\") opens a value that never closes"
                    " (line breaks inside quoted values are not supported)"
                )
            if b"\r" in line:
                raise InputError(
                    f"{where(self.path, row + i)}: a carriage return (\\r) inside the line "
                    "(old Mac line ends, or a corrupt log?); lines must end with \\n or \\r\\n"
                )
            # cells are decoded only to be parsed (voltages) or stored as text (Parquet
            # output, where the block was checked to be UTF-8); the line passes as bytes
            text = line.decode("utf-8", "backslashreplace")
            fields = next(csv.reader([text], delimiter=sep)) if text else []
            if len(fields) > width:
                raise InputError(
                    f"{where(self.path, row + i)}: {len(fields)} fields, expected {width} as in the header "
                    "(a decimal comma, or a separator inside a value?)"
                )
            if self.cut:
                lines.append(kept_fields(line, self.keep, width, sep))
            else:
                lines.append(line + pad * (width - max(1, len(fields))))
            cells.append(fields + [""] * (width - len(fields)))
        cols = list(zip(*cells, strict=True))
        if chunk.truncated:  # no forces whatever it holds: the last number may be cut short
            u = np.full((len(lines), len(self.names)), np.nan)
        else:
            u = np.column_stack([
                to_numbers(cols[j], self.path, n, row, self.settings.decimal, allow_missing=True)
                for j, n in zip(self.index, self.names, strict=True)
            ])
        table = None
        if self.want_table:
            # a block cut short has no forces, but its numbers are kept where they read
            read = u if not chunk.truncated else np.column_stack([
                _lenient(cols[j], self.settings.decimal) for j in self.index])
            table = self._table(read, [pa.array(list(cols[j]), pa.string()) for j in self.keep
                                       if j not in self.float_of])
        return Block(row, u, lines=pa.array(lines, pa.binary()), table=table, done=chunk.done,
                     total=chunk.total, truncated=chunk.truncated)


def _lenient(cells, decimal: str) -> np.ndarray:
    """Each cell as a number, NaN where it reads as none (a cell cut short)."""
    def one(c: str) -> float:
        try:
            return float(c.strip().replace(decimal, ".") if decimal != "." else c)
        except ValueError:
            return np.nan
    return np.array([one(c) for c in cells], dtype=float)


def _lines(body: bytes, buffer: pa.Buffer, rows: int) -> pa.Array:
    """The ``rows`` lines of ``body`` (whole lines, LF ends) as a binary array sharing its memory.

    Element 0 is the first line, element i > 0 the line feed before line i and
    line i: contiguous slices of the block, so no copy is made.  Joined in
    order they give the block minus its final line feed.
    """
    offsets = np.empty(rows + 1, np.int32)
    offsets[0] = 0
    offsets[1:] = np.flatnonzero(np.frombuffer(body, np.uint8) == 10)
    return pa.Array.from_buffers(pa.binary(), rows, [None, pa.py_buffer(offsets), buffer])


def _csv_writable(schema: pa.Schema, path: Path, keep: list[int]) -> None:
    """Refuse, before any row is read, a pass-through column CSV cannot hold as text.

    Lists, structs and maps have no CSV text; Parquet output passes them through.
    """
    for fld in (schema.field(i) for i in keep):
        try:
            pcsv.write_csv(pa.table({"c": pa.array([], fld.type)}), pa.BufferOutputStream())
        except (pa.ArrowInvalid, pa.ArrowNotImplementedError, pa.ArrowTypeError):
            raise InputError(
                f"{where(path, None, fld.name)}: type {fld.type} has no CSV text; write "
                "Parquet output (-o NAME.parquet) to pass it through"
            ) from None


def _binary_as_text(table: pa.Table, path: Path, first_row: int) -> pa.Table:
    """Binary columns as UTF-8 strings for CSV output, or name the first row that is not."""
    for i, fld in enumerate(table.schema):
        if pa.types.is_binary(fld.type) or pa.types.is_large_binary(fld.type):
            try:
                table = table.set_column(i, fld.name, table.column(i).cast(pa.string()))
            except pa.ArrowInvalid:
                for k, v in enumerate(table.column(i).to_pylist()):
                    try:
                        v is None or v.decode("utf-8")
                    except UnicodeDecodeError:
                        shown = v.decode("utf-8", "backslashreplace")
                        raise InputError(
                            f"{where(path, first_row + k, fld.name)}: '{excerpt(shown)}' is "
                            "not UTF-8 text; CSV output writes text as UTF-8 (Parquet output "
                            "passes the bytes through)"
                        ) from None
                raise
    return table


def parquet_blocks(path: Path, names: list[str], settings: Settings, *,
                   chunk_rows: int, to_csv: bool = False,
                   keep: list[int] | None = None) -> Iterator[Block]:
    """The rows of a Parquet log in record batches of at most ``chunk_rows`` rows.

    ``to_csv``: the blocks go to a CSV output, so every column must have a text
    form: nested types are refused before the first row, and binary values must be
    UTF-8 (the row is named).  A list or struct voltage column is refused either way.
    ``keep``: the columns passed through (:func:`~fsdecouple.logs.passthrough.passed_columns`); default all.
    """
    import pyarrow.parquet as pq  # Parquet logs only (see parquet_header)

    try:
        pf = pq.ParquetFile(path, pre_buffer=False, buffer_size=PARQUET_READ_BUFFER)
    except (pa.ArrowInvalid, OSError) as err:
        raise InputError(f"{path}: not a readable Parquet file ({excerpt(err)})") from None
    for n in names:  # before any row is decoded
        if n in pf.schema_arrow.names:
            typ = pf.schema_arrow.field(n).type
            if not (pa.types.is_string(typ) or pa.types.is_large_string(typ)
                    or pa.types.is_integer(typ) or pa.types.is_floating(typ)):
                raise InputError(f"{where(path, None, n)}: type {typ}, expected numbers")
    width = len(pf.schema_arrow)
    keep = list(range(width)) if keep is None else list(keep)
    if to_csv:
        _csv_writable(pf.schema_arrow, path, keep)
    total = max(1, pf.metadata.num_rows)
    row, done = HEADER_ROW + 1, 0
    for batch in pf.iter_batches(batch_size=min(chunk_rows, PARQUET_BATCH_ROWS)):
        table = pa.Table.from_batches([batch])
        voltages = table.select([table.schema.get_field_index(n) for n in names])
        if len(keep) < width:
            table = table.select(keep)
        if to_csv:
            table = _binary_as_text(table, path, row)
        cols = []
        for k, n in enumerate(names):
            col = voltages.column(k)
            if pa.types.is_string(col.type) or pa.types.is_large_string(col.type):
                cols.append(to_numbers(col.fill_null("").to_pylist(), path, n, row, settings.decimal,
                                       allow_missing=True))
            elif pa.types.is_integer(col.type) or pa.types.is_floating(col.type):
                cols.append(column_floats(col))
                inf = np.flatnonzero(np.isinf(cols[-1]))
                if inf.size:  # as in a CSV log: an infinite voltage is no reading
                    raise InputError(f"{where(path, row + int(inf[0]), n)}: is "
                                     f"{float(cols[-1][inf[0]])!r}, expected a finite number")
            else:
                raise InputError(f"{where(path, None, n)}: type {col.type}, expected numbers")
        u = np.column_stack(cols) if cols else np.empty((0, len(names)))
        done += len(table)
        yield Block(row, u, table=table, done=done, total=total)
        row += len(table)


def parquet_header(path: Path) -> tuple[list[str], int]:
    """The column names of a Parquet log, and its rows (at least 1)."""
    # imported for Parquet logs only: pyarrow.parquet loads pyarrow's filesystems (S3's
    # among them), ~30 ms of a CSV apply's start-up
    import pyarrow.parquet as pq

    try:
        if not stat.S_ISREG(os.stat(path).st_mode):  # a FIFO would block; its footer comes first
            raise InputError(f"{printable(path)}: a Parquet log must be a regular file "
                             "(its footer is read first), not a pipe or device")
        with pq.ParquetFile(path) as pf:
            return list(pf.schema_arrow.names), max(1, pf.metadata.num_rows)
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except (pa.ArrowInvalid, OSError) as err:
        raise InputError(f"{path}: not a readable Parquet file ({err})") from None


