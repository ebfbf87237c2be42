"""Decouple a logged voltage file into forces, in blocks (files larger than memory).

Every input row is kept, in order, and every named input column is passed through
as text, unchanged (unnamed columns, repeated names and a side table are dropped:
:func:`~fsdecouple.logs.passthrough.passed_columns`); ``fx, fy, fz`` and ``status`` are
appended.  Forces are in the calibration's load unit, or in the one asked for (``unit``); voltages are in
the data's output unit (:mod:`fsdecouple.units`).  ``status`` says what the
forces of the row are worth (:data:`STATUSES`); rows that cannot be decoupled
keep empty forces and are counted.  CSV output uses the log's dialect (``sep``,
``decimal``); Parquet output records the units in its schema metadata
(:data:`FORCE_UNIT_KEY`, :data:`OUTPUT_UNIT_KEY`).
"""

from __future__ import annotations

import contextlib
import itertools
import os
import queue
import threading
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow.compute as pc

from ..axes import FORCE_COLUMNS, VOLTAGE_COLUMNS
from ..config import Settings
from ..core.model import FORCE_LIMIT, CouplingErrorModel
from ..data.csv_text import HEADER_ROW, require_columns
from ..data.zero import tare_offsets
from ..errors import InputError, where
from ..evaluation.intervals import half_widths, interval_names, with_intervals
from ..files.outputs import atomic_write, refuse_overwriting_input
from ..schema import refuse_unused, unused_warning
from ..units import LOAD_UNITS, load_factor
from .arrow import numbers, strings
from .outputs import (
    beyond_temperatures,
    input_names,
    input_scale,
    limit_bounds,
    log_outputs,
    row_forces,
)
from .passthrough import Dropped, kept_fields, passed_columns
from .reader import Block, LogFile, is_parquet
from .sinks import CsvSink, ParquetSink, force_decimals
from .untared import block_median, untared

CHUNK_ROWS = 1 << 20  # rows per block at most; blocks are cut at ~4 MB anyway
MAX_WORKERS = 4
# A log of this many chi evaluations (core/table_path.py TableDecoupler.work) is
# decoupled by the compiled kernel, a shorter one in numpy.  Measured in apply's CPU
# time (user, less scattered than the wall clock here): loading the kernel costs ~0.7 s
# of CPU (0.45 s of wall clock in a fresh process), and it saved 3-6 ns an evaluation
# (10 M six-axis rows: ~1 s of 300 M; 10 M 3-axis rows at K = 3: 1.25 s of 240 M; 30 M
# 3-axis rows: ~1.1 s of 180 M), so it pays from about 2^27: a 3-axis log of 22 M rows
# at K = 0, 5.6 M at K = 3, six axes from 4.5 M (docs/design/performance.md).  A pipe,
# whose length is unknown, leaves it to each block (COMPILED_WORK, a call's rule).
APPLY_COMPILED_WORK = 1 << 27
STATUS_COLUMN = "status"
FORCE_UNIT_KEY, OUTPUT_UNIT_KEY = "fsdecouple.force_unit", "fsdecouple.output_unit"
# What a row's forces are worth.  Only "ok", "extrapolated" and "saturated" rows
# have forces.  A row takes the first that applies of: truncated, missing,
# not_finite (no forces), saturated, extrapolated, ok.
STATUSES = {
    "ok": "decoupled by eq. (11), voltages inside the calibrated range",
    "extrapolated": "decoupled, but a voltage (or the temperature) lies outside the calibrated range",
    "saturated": "decoupled, but a raw output is at or beyond its limit (limits:): it may "
                 "have clipped",
    "missing": "a voltage is empty or missing (blank or short row): no forces",
    "truncated": "last line of a log that does not end with a newline (the writer "
                 "was cut off, a number may be cut short): no forces",
    "not_finite": "a force is not finite (eq. (11) overflows) or beyond model.FORCE_LIMIT "
                  "times the largest full-scale load: no forces",
    "not_converged": "the model's second-order refinement (refine: K) did not settle "
                     "for this row (decouple.REFINE_TOLERANCE): no forces",
}
STATUS_NAMES = strings(STATUSES)
OK_, EXTRAPOLATED_, SATURATED_, MISSING_, TRUNCATED_, NOT_FINITE_, NOT_CONVERGED_ = range(
    len(STATUSES))


@dataclass
class ApplySummary:
    """What ``apply`` did: rows written, per-status counts, the zero removed.

    ``offsets`` are in ``output_unit``, the forces written in ``force_unit``.
    """

    rows: int = 0
    missing_rows: int = 0
    first_missing: list[int] = field(default_factory=list)
    out_of_range_rows: int = 0
    saturated_rows: int = 0
    truncated_rows: int = 0
    not_finite_rows: int = 0
    status_counts: dict[str, int] = field(default_factory=lambda: dict.fromkeys(STATUSES, 0))
    offsets: np.ndarray = field(default_factory=lambda: np.zeros(3))
    force_unit: str = "N"
    output_unit: str = "V"
    outputs: tuple[str, ...] = VOLTAGE_COLUMNS  # the names of ``offsets``
    temperature_unit: str | None = None  # a fitted model's: its input after the outputs
    force_columns: tuple[str, ...] = FORCE_COLUMNS  # the columns written (force_columns)
    dropped: list[Dropped] = field(default_factory=list)  # log columns not passed through
    untared: tuple[str, float, float, float] | None = None  # untared.py: (output, median, lo, hi)
    notes: list[str] = field(default_factory=list)  # config keys not used (schema.unused_warning)

    def to_dict(self) -> dict:
        """The ``apply --json`` document of one log."""
        return {"rows": self.rows, "force_columns": list(self.force_columns),
                "force_unit": self.force_unit, "output_unit": self.output_unit,
                "status_counts": dict(self.status_counts),
                "dropped_columns": [vars(d) for d in self.dropped],
                "offsets": dict(zip(self.outputs, map(float, self.offsets), strict=True))}


def force_columns(loads, header) -> tuple[str, ...]:
    """The names of ``apply``'s force columns: never a name the log already has.

    Each component's load name (``fx`` .. ``mz``), prefixed with ``decoupled_`` while
    the log has a column of that name in any case: a sensor's own readings named
    ``Fx .. Mz`` get ``decoupled_fx .. decoupled_mz`` beside them.
    """
    taken = {str(h).lower() for h in header} | {STATUS_COLUMN}
    out = []
    for c in loads:
        name = c
        while name.lower() in taken:
            name = f"decoupled_{name}"
        taken.add(name.lower())
        out.append(name)
    return tuple(out)


def apply_file(
    model: CouplingErrorModel,
    voltages: str | Path,
    out: str | Path,
    *,
    settings: Settings | None = None,
    tare: int | None = None,
    zero: tuple[float, float, float] | None = None,
    unit: str | None = None,
    force: bool = False,
    chunk_rows: int = CHUNK_ROWS,
    progress: Callable[[int, int], None] | None = None,
    workers: int | None = None,
    round_trip: bool = False,
    interval: float | None = None,
    temperature: float | None = None,
) -> ApplySummary:
    """Decouple the voltage log ``voltages`` into ``out`` by eq. (11).

    Parameters
    ----------
    settings : Settings, optional
        Column names, scales, CSV dialect and ``limits`` of the log; default:
        the model's.  Without ``limits`` of its own, the model's apply.
    tare : int, optional
        Subtract the mean voltages of the first ``tare`` rows (task-data zero).
    zero : (float, float, float), optional
        Subtract these voltages [output unit of the model] instead.
    unit : str, optional
        Load unit of the forces written (:data:`~fsdecouple.units.LOAD_UNITS`);
        default: the calibration's, ``model.settings.load_unit``.
    progress : callable, optional
        Called as ``progress(done, total)`` in bytes (CSV) or rows (Parquet).
    workers : int, optional
        Threads parsing, decoupling and formatting blocks; default: the cores, at
        most 4 (each block in flight holds ~60 MB).
    round_trip : bool
        CSV output: write each force as the shortest text that reads back as
        the same double.  By default forces are rounded to the decimals that
        keep them within 1e-10 of full-scale load
        (:func:`~fsdecouple.logs.sinks.force_decimals`, 8 decimals for the
        paper's sensor in N), a tenth of the fast path's 1e-9.  Parquet output
        always stores the doubles.
    temperature : float, optional
        The temperature reading of every row, for a log without the model's temperature
        column (:mod:`fsdecouple.logs.outputs`).
    interval : float, optional
        Add ``<component>_lo`` and ``<component>_hi``: bounds holding the true force
        with probability ``interval`` (0 < P < 1), by conformal prediction on the
        fit's held-out residuals (:mod:`fsdecouple.evaluation.intervals`).

    Notes
    -----
    Rows with a raw output (after ``scale:``, before the tare or zero) at or
    beyond its ``limits`` get the status ``saturated``; their forces are written.

    The input and output formats follow the file suffixes: ``.parquet`` (or
    ``.pq``) is Parquet, anything else CSV.  CSV lines pass through byte for
    byte; Parquet columns keep their types, and a CSV's columns become strings
    there except the outputs the model reads, written as the doubles read (a
    missing cell null).
    """
    path, out = Path(voltages), Path(out)
    settings, unit = check_options(model, settings, tare, zero, unit)
    if interval is not None:
        half_widths(model, interval)  # refused before the log is read
    refuse_overwriting_input(out, [path])
    with LogFile(path, settings) as log:
        return _apply(model, log, out, settings, tare, zero, unit, force, chunk_rows, progress,
                      workers, round_trip, interval, temperature)


def check_options(model: CouplingErrorModel, settings: Settings | None, tare, zero,
                  unit: str | None) -> tuple[Settings, str]:
    """``apply``'s settings and force unit, with the defaults; refused if they cannot be used."""
    settings = settings or model.settings
    refuse_unused(settings, model.settings, "apply")
    if settings.units != model.settings.units:
        # the model's k and ranges are in its calibration's units: a log in others
        # would be decoupled silently wrong by a factor of 1000 or more
        raise InputError(
            f"the config's units ({settings.output_unit} outputs, {settings.load_unit} loads) are "
            f"not the model's ({model.settings.output_unit}, {model.settings.load_unit}); "
            "convert the log with scale: or use the calibration's config")
    if tare is not None and zero is not None:
        raise InputError("give either --tare or --zero, not both")
    if settings.layout != model.layout:
        raise InputError(
            f"the config names outputs {', '.join(settings.layout.outputs)}, the model "
            f"{', '.join(model.layout.outputs)}; use the calibration's config")
    if zero is not None and len(zero) != model.n_inputs:
        raise InputError(f"--zero: {len(zero)} values for the model's {model.n_inputs} "
                         f"inputs ({', '.join(input_names(model))})")
    if unit is not None and model.settings.units.loads:
        raise InputError(f"--unit {unit}: the model's loads have mixed units "
                         f"({model.settings.load_unit}); they are written in their own")
    given, unit = unit is not None, model.settings.load_unit if unit is None else unit
    if given and unit not in LOAD_UNITS or model.settings.load_unit not in LOAD_UNITS and given:
        raise InputError(f"--unit {unit!r}: unknown load unit; expected one of "
                         f"{', '.join(LOAD_UNITS)}")
    return settings, unit


def read_tare(blocks: Iterable[Block], scale: np.ndarray, tare: int,
              source) -> tuple[np.ndarray, list[Block]]:
    """``--tare``: the zero of a log's first ``tare`` rows, and the blocks read for it.

    ``blocks`` are read only as far as the tare rows reach (the rest stay unread);
    ``scale`` is the config's per-output ``scale:``.
    """
    head, kept, n = [], [], 0
    for block in blocks:
        kept.append(block)
        head.append(block.u[:tare - n] * scale)
        n += len(head[-1])
        if n >= tare:
            break
    rows = np.concatenate(head) if head else np.empty((0, len(scale)))
    return tare_offsets(rows, tare, source=source), kept


@dataclass(frozen=True)
class RowRules:
    """What decides a row's status besides its values: extrapolation and saturation bounds."""

    lo: np.ndarray  # model.extrapolation_limits(), zero-corrected outputs
    hi: np.ndarray
    sat_lo: np.ndarray  # limits: raw outputs (after scale:, before the zero)
    sat_hi: np.ndarray

    @property
    def limited(self) -> list[int]:
        """The raw columns with a saturation limit (``limits:``); the rest are +-inf."""
        return [k for k in range(len(self.sat_lo))
                if np.isfinite(self.sat_lo[k]) or np.isfinite(self.sat_hi[k])]

    @classmethod
    def for_model(cls, model: CouplingErrorModel, settings: Settings | None = None) -> RowRules:
        return cls(*model.extrapolation_limits().T, *limit_bounds(settings or model.settings, model))


def _any_column(a: np.ndarray, test: Callable[[np.ndarray, int], np.ndarray],
                columns=None) -> np.ndarray:
    """Rows (n,) of ``a`` (n, m) where ``test(column, k)`` holds for any column k
    (of ``columns``, default all).

    The same as ``test`` on the whole array and ``.any(axis=1)``, column by column:
    numpy reduces a few columns a row some 10x slower than it ORs whole columns.
    """
    hit = np.zeros(len(a), dtype=bool)
    for k in range(a.shape[1]) if columns is None else columns:
        hit |= test(a[:, k], k)
    return hit


def decouple_rows(model: CouplingErrorModel, raw: np.ndarray, offsets: np.ndarray,
                  rules: RowRules, *, truncated: bool = False, compiled: bool | None = None):
    """Eq. (11) and a status per row: ``(forces, status code, no-forces mask)``.

    ``raw``: outputs as read (after ``scale:``); ``offsets``: the zero subtracted;
    ``compiled``: the table path's compiled kernel, as ``model.decouple`` (default: by
    the block's work; ``apply`` decides for the whole log, :func:`log_compiled`).
    The one place that decides a row's status (:data:`STATUSES`), for ``apply``'s
    blocks and for :func:`fsdecouple.logs.frame.decouple_frame` alike.
    """
    u = model.zero_corrected(raw, offsets)  # the plan's temperature step, if any
    code = np.zeros(len(u), dtype=np.int8)  # index into STATUSES
    empty = _any_column(u, lambda c, k: np.isnan(c))
    code[empty] = MISSING_
    if truncated:
        # a writer that crashed mid-line: the fields may look complete but the last
        # number be cut short, so the row gets no forces
        empty[:] = True
        code[:] = TRUNCATED_
    converged = np.empty(len(u), dtype=bool)
    with np.errstate(over="ignore", invalid="ignore"):
        f = row_forces(model, u, raw, offsets, empty, converged, compiled)  # logs/outputs.py
        unsettled = ~converged & ~empty
        code[unsettled] = NOT_CONVERGED_
        empty |= unsettled
        # not finite, or beyond FORCE_LIMIT x full scale: physically meaningless
        bound = FORCE_LIMIT * float(np.max(np.abs(model.settings.full_scale)))
        huge = _any_column(f, lambda c, k: ~(np.abs(c) <= bound)) & ~empty
        code[huge] = NOT_FINITE_
        empty |= huge
        x = u if model.projection is None else model.project(u)  # M > N: the limits are v's
        outside = _any_column(x, lambda c, k: (c < rules.lo[k]) | (c > rules.hi[k])) & ~empty
        outside |= beyond_temperatures(model, raw) & ~empty
        # the limits are the ADC's or amplifier's, so they bound the raw values; a column
        # without limits (+-inf, the default) is not scanned: only an infinite raw value
        # could meet them, and its row has no forces (empty) already
        saturated = _any_column(raw, lambda c, k: (c <= rules.sat_lo[k]) | (c >= rules.sat_hi[k]),
                                rules.limited) & ~empty
    code[outside] = EXTRAPOLATED_
    code[saturated] = SATURATED_
    return f, code, empty


def log_compiled(block: Block, tables, refine: int) -> bool | None:
    """Whether the whole log is APPLY_COMPILED_WORK or more, its rows estimated from the
    block's progress through the file (bytes of CSV, rows of Parquet); None, the
    block's own rule, for a pipe (its length unknown) or a model without tables."""
    if tables is None or not block.total or not block.done:
        return None
    rows = (block.first_row - HEADER_ROW - 1 + len(block)) * block.total / block.done
    return tables.work(rows, refine) >= APPLY_COMPILED_WORK


def _apply(model, log: LogFile, out: Path, settings: Settings, tare, zero, unit, force,
           chunk_rows, progress, workers, round_trip, interval=None, temperature=None) -> ApplySummary:
    path = log.path
    layout = model.layout
    read, with_temperature = log_outputs(model, settings, log.header, path, temperature)
    names = list(read.values())
    require_columns(log.header, read, path)
    # unnamed columns, repeated names and a side table are not passed through
    keep, dropped = passed_columns(log.header, names)
    header = [log.header[i] for i in keep]
    header_line = log.header_line
    if dropped and not log.parquet:
        header_line = kept_fields(header_line, keep, len(log.header), settings.sep)
    if STATUS_COLUMN in header:
        raise InputError(
            f"{where(path, HEADER_ROW, STATUS_COLUMN)}: the log already has a column named "
            f"'{STATUS_COLUMN}', which the output would overwrite"
        )
    forces = force_columns(layout.loads, header)
    columns = forces + (interval_names(forces) if interval is not None else ())
    taken = {str(h).lower() for h in header}
    clash = [c for c in columns[len(forces):] if c.lower() in taken]
    if clash:
        raise InputError(f"{where(path, HEADER_ROW, clash[0])}: the log already has a column named "
                         f"'{clash[0]}', which the output would overwrite")
    scale = input_scale(model, settings)  # a fitted model's temperature after the outputs
    jobs: Iterator[Callable[[], Block]] = log.blocks(names, chunk_rows=chunk_rows,
                                                     want_table=is_parquet(out), keep=keep)
    jobs = with_temperature(jobs)
    summary = ApplySummary(force_unit=unit, output_unit=model.settings.output_unit,
                           outputs=input_names(model), offsets=np.zeros(model.n_inputs),
                           temperature_unit=(model.temperature.unit
                                             if model.n_inputs > model.n_outputs else None),
                           force_columns=forces, dropped=dropped,
                           notes=unused_warning(settings, model.settings))
    to_unit = load_factor(model.settings.load_unit, unit)
    sat_lo, sat_hi = limit_bounds(settings, model)
    if tare is not None:
        # the tare rows are read once: their blocks are kept and decoupled first
        summary.offsets, kept = read_tare((job() for job in jobs), scale, tare, path)
        jobs = itertools.chain((lambda block=block: block for block in kept), jobs)
    elif zero is not None:
        summary.offsets = np.asarray(zero, dtype=float)
    elif model.zero is not None:  # zero: intercept: the offsets fitted with the loads
        summary.offsets = np.asarray(model.zero, dtype=float)
    rows, medians = RowRules(*model.extrapolation_limits().T, sat_lo, sat_hi), []
    # blocks in flight bound the memory (~60 MB each), so not every core of a big box
    workers = workers or min(MAX_WORKERS, os.cpu_count() or 1)
    tables = model.fast_decoupler()

    with atomic_write(out, "wb", force=force) as fh:
        if is_parquet(out):
            sink = ParquetSink(fh, (STATUS_COLUMN,), {FORCE_UNIT_KEY: unit,
                                                      OUTPUT_UNIT_KEY: summary.output_unit},
                               columns=columns)
        else:
            full_scale = np.asarray(model.settings.full_scale) * to_unit
            decimals = None if round_trip else force_decimals(full_scale)
            sink = CsvSink(fh, header, None if log.parquet else header_line, decimals,
                           sep=settings.sep, decimal=settings.decimal, extra=(STATUS_COLUMN,),
                           columns=columns)

        def work(job):
            # parse, eq. (11) and format one block; numpy and pyarrow release the
            # GIL, so blocks overlap on the cores while the main thread writes
            block = job()
            f, code, empty = decouple_rows(model, block.u * scale, summary.offsets, rows,
                                           truncated=block.truncated,
                                           compiled=log_compiled(block, tables,
                                                                 model.settings.refine))
            if interval is not None:
                f = with_intervals(model, f, interval, model.zero_corrected(block.u * scale, summary.offsets))
            if to_unit != 1.0:
                f = f * to_unit
            counts = np.bincount(code, minlength=len(STATUSES))
            first = np.flatnonzero(code == MISSING_)[:10] + block.first_row if counts[MISSING_] \
                else ()
            status = pc.take(STATUS_NAMES, numbers(code))
            if tare is None and zero is None and len(block):
                medians.append(block_median(block.u, scale))
            return len(block), counts, first, block.done, block.total, \
                sink.encode(block, f, empty, (status,))

        try:
            with ThreadPoolExecutor(workers) as pool:
                pending: deque = deque()
                for job in _prefetch(jobs, workers + 1):
                    pending.append(pool.submit(work, job))
                    while len(pending) > workers or (pending and pending[0].done()):
                        _collect(pending.popleft().result(), sink, summary, progress)
                while pending:
                    _collect(pending.popleft().result(), sink, summary, progress)
        except BaseException:
            # a Parquet writer left open would fail again when collected, after the
            # temporary file is gone: a second message under the one-line error
            with contextlib.suppress(Exception):
                sink.close()
            raise
        sink.close()
        if summary.rows == 0:
            raise InputError(f"{path}: header only, no data rows")
    summary.untared = untared(summary, medians, None if model.projection is not None else rows)
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
    n, counts, first, done, total, payload = result
    sink.write(payload)
    summary.rows += n
    for name, k in zip(STATUSES, counts, strict=True):
        summary.status_counts[name] += int(k)
    summary.missing_rows += int(counts[MISSING_])
    summary.truncated_rows += int(counts[TRUNCATED_])
    summary.not_finite_rows += int(counts[NOT_FINITE_])
    summary.out_of_range_rows += int(counts[EXTRAPOLATED_])
    summary.saturated_rows += int(counts[SATURATED_])
    summary.first_missing += [int(r) for r in first[:10 - len(summary.first_missing)]]
    if progress is not None:
        progress(done, total)
