"""Decouple a logged voltage file into forces, in chunks (files larger than memory).

Every input column is passed through as text, unchanged and in order; ``fx, fy,
fz`` [N] are appended.  Rows with a missing voltage are kept with empty forces
and counted.
"""

from __future__ import annotations

import os
import queue
import threading
from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np

from .config import FORCE_COLUMNS, VOLTAGE_COLUMNS, Settings
from .errors import InputError, where
from .io import HEADER_ROW, atomic_write, read_header, require_columns
from .model import CouplingErrorModel
from .stream import (
    Block,
    CsvParser,
    CsvSink,
    ParquetSink,
    csv_bodies,
    csv_eol,
    force_decimals,
    is_parquet,
    parquet_blocks,
    parquet_header,
)
from .zero import tare_offsets

CHUNK_ROWS = 1 << 20  # rows per block at most; blocks are cut at ~4 MB anyway
MAX_WORKERS = 4


@dataclass
class ApplySummary:
    rows: int = 0
    missing_rows: int = 0
    first_missing: list[int] = field(default_factory=list)
    out_of_range_rows: int = 0
    offsets: np.ndarray = field(default_factory=lambda: np.zeros(3))


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
    workers: int | None = None,
    round_trip: bool = False,
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
        Called as ``progress(done, total)`` in bytes (CSV) or rows (Parquet).
    workers : int, optional
        Threads parsing, decoupling and formatting blocks; default: the cores, at
        most 4 (each block in flight holds ~60 MB).
    round_trip : bool
        CSV output: write each force as the shortest text that reads back as
        the same double.  By default forces are rounded to the decimals that
        keep them within 1e-10 V-equivalent (:func:`~fsdecouple.stream.force_decimals`,
        8 decimals for the paper's sensor), a tenth of the fast path's 1e-9 V.
        Parquet output always stores the doubles.

    The input and output formats follow the file suffixes: ``.parquet`` (or
    ``.pq``) is Parquet, anything else CSV.  CSV lines pass through byte for
    byte; Parquet columns keep their types (CSV columns become strings).
    """
    path, out = Path(voltages), Path(out)
    settings = settings or model.settings
    if tare is not None and zero is not None:
        raise InputError("give either --tare or --zero, not both")
    parquet_in = is_parquet(path)
    header = parquet_header(path) if parquet_in else read_header(path, settings)
    names = [settings.columns[c] for c in VOLTAGE_COLUMNS]
    require_columns(header, dict(zip(VOLTAGE_COLUMNS, names, strict=True)), path)
    clash = [c for c in FORCE_COLUMNS if c in header]
    if clash:
        raise InputError(
            f"{where(path, HEADER_ROW, clash[0])}: the log already has a column named "
            f"'{clash[0]}', which the output would overwrite"
        )
    scale = np.array([settings.scale[c] for c in VOLTAGE_COLUMNS])

    def jobs() -> Iterator[Callable[[], Block]]:
        """Blocks to parse, in file order; CSV blocks are parsed by the workers."""
        if parquet_in:
            for b in parquet_blocks(path, names, settings, chunk_rows=chunk_rows):
                yield lambda b=b: b
            return
        parse = CsvParser(path, header, names, settings, csv_eol(path), is_parquet(out))
        for body in csv_bodies(path, chunk_rows=chunk_rows):
            yield partial(parse, body)

    summary = ApplySummary()
    if tare is not None:
        head, n = [], 0
        for job in jobs():
            head.append(job().u[:tare - n] * scale)
            n += len(head[-1])
            if n >= tare:
                break
        summary.offsets = tare_offsets(np.concatenate(head) if head else np.empty((0, 3)), tare)
    elif zero is not None:
        summary.offsets = np.asarray(zero, dtype=float)
    lo, hi = model.calibrated_range.T
    # blocks in flight bound the memory (~60 MB each), so not every core of a big box
    workers = workers or min(MAX_WORKERS, os.cpu_count() or 1)

    with atomic_write(out, "wb", force=force) as fh:
        if is_parquet(out):
            sink = ParquetSink(fh)
        else:
            decimals = None if round_trip else force_decimals(model.k)
            sink = CsvSink(fh, header, None if parquet_in else _header_line(path), decimals)

        def work(job):
            # parse, eq. (11) and format one block; numpy and pyarrow release the
            # GIL, so blocks overlap on the cores while the main thread writes
            block = job()
            u = block.u * scale - summary.offsets
            missing = np.isnan(u).any(axis=1)
            f = model.decouple(u, workers=1)
            ok = ~missing
            outside = int(((u[ok] < lo) | (u[ok] > hi)).any(axis=1).sum())
            rows = np.flatnonzero(missing)[:10] + block.first_row
            return len(block), int(missing.sum()), rows, outside, block.done, block.total, \
                sink.encode(block, f, missing)

        with ThreadPoolExecutor(workers) as pool:
            pending: deque = deque()
            for job in _prefetch(jobs(), workers + 1):
                pending.append(pool.submit(work, job))
                while len(pending) > workers or (pending and pending[0].done()):
                    _collect(pending.popleft().result(), sink, summary, progress)
            while pending:
                _collect(pending.popleft().result(), sink, summary, progress)
        sink.close()
        if summary.rows == 0:
            raise InputError(f"{path}: header only, no data rows")
    return summary


def _prefetch(items: Iterator, depth: int) -> Iterator:
    """``items`` produced by a background thread, at most ``depth`` ahead.

    Reading the next block (file I/O, Parquet decoding) then overlaps with
    writing the last one on the main thread.
    """
    q: queue.Queue = queue.Queue(depth)
    stop = threading.Event()
    end = object()

    def put(entry) -> bool:
        while not stop.is_set():  # never block for good: the consumer may be gone
            try:
                q.put(entry, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def produce() -> None:
        try:
            for item in items:
                if not put((item, None)):
                    return
            put((end, None))
        except BaseException as err:  # noqa: B036 - handed over to the consumer as is
            put((end, err))

    thread = threading.Thread(target=produce, name="fsdecouple-read", daemon=True)
    thread.start()
    try:
        while True:
            item, err = q.get()
            if err is not None:
                raise err
            if item is end:
                return
            yield item
    finally:
        stop.set()
        thread.join()


def _collect(result, sink, summary: ApplySummary, progress) -> None:
    n, n_missing, rows, outside, done, total, payload = result
    sink.write(payload)
    summary.rows += n
    summary.missing_rows += n_missing
    summary.first_missing += [int(r) for r in rows[:10 - len(summary.first_missing)]]
    summary.out_of_range_rows += outside
    if progress is not None:
        progress(done, total)


def _header_line(path: Path) -> bytes:
    with open(path, "rb") as fh:
        return fh.readline().removeprefix(b"\xef\xbb\xbf").rstrip(b"\r\n")
