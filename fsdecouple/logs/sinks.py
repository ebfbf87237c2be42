"""Write a decoupled log: the input rows passed through, forces and status appended."""

from __future__ import annotations

import io
import json

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pcsv

from ..axes import FORCE_COLUMNS
from .arrow import binary, numbers
from .passthrough import csv_row
from .reader import Block


def force_arrays(f: np.ndarray, empty: np.ndarray) -> list[pa.Array]:
    """Forces (n, N) as Arrow doubles, one array a column, null where ``empty``."""
    return [numbers(f[:, k].astype(np.float64), empty) for k in range(f.shape[1])]


def force_decimals(full_scale, budget: float = 1e-10) -> int:
    """Decimals that round each force by at most ``budget`` of its full-scale load.

    ``full_scale``: the full-scale loads, in the unit the forces are written in.
    A fraction of full scale is unit-invariant: newtons, gram-force and kN
    keep the same relative precision, and so do volts, mV and counts, since
    |df| <= budget * F_FS is |df| * |k| <= budget * |k| F_FS, a fraction of the
    full-scale output.  1e-10 keeps the fast path's 1e-9 promise with room to
    spare (8 decimals for the paper's sensor) and is 30 % shorter than
    round-trip text: on a 10 M-row log that is 200 MB less to write.
    """
    step = 2.0 * budget * float(np.min(np.abs(full_scale)))  # rounding error <= step / 2
    return max(0, int(np.ceil(-np.log10(step))))


class CsvSink:
    """Writes blocks as CSV: the input line (or columns), ``fx, fy, fz``, ``status``.

    Written in the log's dialect: fields joined by ``sep``, forces with ``decimal``.
    ``decimals``: forces are rounded to this many decimals before their
    shortest text is written; None writes round-trip text of the doubles.
    """

    def __init__(self, fh, header: list[str], header_line: bytes | None,
                 decimals: int | None = None, *, sep: str = ",", decimal: str = ".",
                 extra: tuple[str, ...] = (), columns: tuple[str, ...] = FORCE_COLUMNS):
        self.fh = fh
        self.columns = columns
        self.header = header
        self.decimals = decimals
        self.sep, self.decimal = sep, decimal
        # the input's own header line as it is, else the names quoted where they must be
        line = (header_line.decode("utf-8", "surrogateescape") if header_line is not None
                else csv_row(header, sep))
        fh.write((line + sep + csv_row([*columns, *extra], sep)).encode("utf-8", "surrogateescape")
                 + b"\n")

    def _text(self, a: pa.Array) -> pa.Array:
        text = pc.cast(a, pa.string())
        if self.decimal != ".":
            text = pc.replace_substring(text, ".", self.decimal)
        return text

    def encode(self, block: Block, f: np.ndarray, empty: np.ndarray, extra: tuple = ()):
        """The block's output bytes; thread-safe, so blocks can be encoded in parallel.

        ``empty``: rows written with empty forces; ``extra``: string arrays appended.
        """
        if self.decimals is not None:
            # rounding scales by 10**decimals: near 1e300 that overflows, and a finite
            # force must never be written as inf; such values keep their own digits
            with np.errstate(over="ignore", invalid="ignore"):
                rounded = np.round(f, self.decimals)
            f = np.where(np.isfinite(rounded) | ~np.isfinite(f), rounded, f)
        text = [self._text(a) for a in force_arrays(f, empty)]
        if block.lines is not None:
            parts = [a.cast(pa.binary()) for a in (*text, *extra)]
            out = pc.binary_join_element_wise(
                block.lines, *parts, binary(self.sep.encode()), null_handling="replace",
                null_replacement=b"",
            )
            if not block.joined:
                out = pc.binary_join_element_wise(out, binary(b""), binary(b"\n"))
            offsets = np.frombuffer(out.buffers()[1], np.int32)[out.offset:out.offset + len(out) + 1]
            data = memoryview(out.buffers()[2])[offsets[0]:offsets[-1]]
            return [data, b"\n"] if block.joined else [data]
        table = block.table
        if self.decimal != ".":  # pass-through floats (Parquet input) in the log's dialect too
            for i, fld in enumerate(table.schema):
                if pa.types.is_floating(fld.type):
                    table = table.set_column(i, fld.name, self._text(table.column(i)))
        for c, a in zip(self.columns, text, strict=True):
            table = table.append_column(c, a)
        for k, a in enumerate(extra):
            table = table.append_column(f"_extra{k}", a)
        sink = io.BytesIO()
        try:  # plain text as a CSV log has it; quotes only if a value needs them
            pcsv.write_csv(table, sink, pcsv.WriteOptions(
                include_header=False, delimiter=self.sep, quoting_style="none"))
        except pa.ArrowInvalid:
            sink = io.BytesIO()
            pcsv.write_csv(table, sink, pcsv.WriteOptions(include_header=False, delimiter=self.sep))
        return [sink.getbuffer()]

    def write(self, payload) -> None:
        for part in payload:
            self.fh.write(part)

    def close(self) -> None:
        pass


def pandas_metadata(schema: pa.Schema) -> bytes:
    """The ``pandas`` schema metadata of a table of ``schema`` read as pandas reads it by
    default: the one every engine writes, so that a dataset's parts agree (Dask's own
    said ``double[pyarrow]``, an input's listed only the input's columns).

    Numbers, booleans and strings (every column of a log and of apply's output) are
    written here as pyarrow writes them from pandas >= 3, without importing pandas
    (0.8 s of a Parquet ``apply``); other types, or an older pandas, through pandas.
    """
    simple = _plain_pandas_metadata(schema)
    if simple is not None:
        return simple
    plain = schema.remove_metadata().empty_table().to_pandas()
    return pa.Schema.from_pandas(plain, preserve_index=False).metadata[b"pandas"]


def _plain_pandas_metadata(schema: pa.Schema) -> bytes | None:
    from importlib import metadata  # 45 ms of imports: for Parquet output only

    try:
        version = metadata.version("pandas")
    except metadata.PackageNotFoundError:
        return None
    if not version.split(".")[0].isdigit() or int(version.split(".")[0]) < 3:
        return None
    columns = []
    for f in schema:
        if pa.types.is_string(f.type) or pa.types.is_large_string(f.type):
            kinds = ("object", "str")
        elif pa.types.is_integer(f.type) or pa.types.is_floating(f.type) or pa.types.is_boolean(f.type):
            kinds = (str(f.type.to_pandas_dtype().__name__),) * 2
        else:
            return None
        columns.append({"name": f.name, "field_name": f.name, "pandas_type": kinds[0],
                        "numpy_type": kinds[1], "metadata": None})
    return json.dumps({"index_columns": [], "column_indexes": [], "columns": columns,
                       "attributes": {}, "creator": {"library": "pyarrow", "version": pa.__version__},
                       "pandas_version": version}).encode()


def parquet_options(schema: pa.Schema) -> dict:
    """The writer's encoding options for a decoupled log, shared by apply and the Dask engine.

    Measured doubles seldom repeat and do not compress: dictionary-encoding or
    Snappy-compressing them is wasted work (Snappy saved < 0.1 % on them), so float
    columns are written plain; the rest keep pyarrow's defaults (dictionary, Snappy).
    Every column is named: pyarrow leaves a column missing from the dict uncompressed.
    """
    return {"use_dictionary": [f.name for f in schema if not pa.types.is_floating(f.type)],
            "compression": {f.name: "none" if pa.types.is_floating(f.type) else "snappy"
                            for f in schema}}


class ParquetSink:
    """Writes blocks as Parquet: the input columns, ``fx, fy, fz`` as doubles, extras.

    ``metadata``: key-value pairs added to the schema's metadata (the units).
    """

    def __init__(self, fh, extra: tuple[str, ...] = (), metadata: dict[str, str] | None = None,
                 columns: tuple[str, ...] = FORCE_COLUMNS):
        self.fh = fh
        self.columns = columns
        self.extra = extra
        self.metadata = {k.encode(): v.encode() for k, v in (metadata or {}).items()}
        self.writer = None  # a pyarrow.parquet.ParquetWriter from the first block

    def encode(self, block: Block, f: np.ndarray, empty: np.ndarray, extra: tuple = ()) -> pa.Table:
        table = block.table
        for c, a in zip(self.columns, force_arrays(f, empty), strict=True):
            table = table.append_column(c, a)
        for c, a in zip(self.extra, extra, strict=True):
            table = table.append_column(c, a)
        return table

    def write(self, table: pa.Table) -> None:
        if self.writer is None:
            import pyarrow.parquet as pq  # Parquet output only (reader.parquet_header)

            schema = table.schema.with_metadata({**(table.schema.metadata or {}), **self.metadata,
                                                 b"pandas": pandas_metadata(table.schema)})
            self.writer = pq.ParquetWriter(self.fh, schema, **parquet_options(table.schema))
        self.writer.write_table(table)

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
