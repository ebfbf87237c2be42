"""The Dask engine of many-log ``apply`` (``--engine dask``).

* A CSV log (or a single Parquet file) is one task, which runs the local engine's
  own per-log core (:func:`fsdecouple.logs.many.apply_job`, that is ``apply_file``):
  the bytes written are the local engine's.
* A Parquet dataset is read with ``dask.dataframe.read_parquet``, one partition
  per part file, decoupled by :func:`decouple_partition` (``decouple_frame``,
  the same arithmetic and statuses as ``apply``) in ``map_partitions``, and
  written back with ``to_parquet``: one part per partition, under the input
  part's name, so the partitioning is the input's.  Forces are Arrow doubles,
  null where a row has none, as ``apply`` writes them.

Tasks write into the run's staging directory under ``OUT_DIR``, which the workers
must see (a LocalCluster does; a remote cluster needs shared storage), and the
client moves each finished output into place.  A worker that dies mid-task is
replaced and its task run again by Dask (up to the scheduler's
``allowed-failures``, 3 by default); after that the log is reported failed, and
its partial files go with the staging directory.

Dask is imported here only, inside functions: ``fsdecouple`` works without it.
"""

from __future__ import annotations

import contextlib
import logging
import os
import uuid
from collections.abc import Callable

import numpy as np

from ..errors import FsdecoupleError, InputError, excerpt, printable
from ..evaluation.intervals import interval_names
from ..units import load_factor
from .apply import (
    FORCE_UNIT_KEY,
    OUTPUT_UNIT_KEY,
    STATUS_COLUMN,
    STATUS_NAMES,
    check_options,
    force_columns,
)
from .frame import frame_forces, frame_outputs
from .jobs import ApplySpec, Job, apply_job, dataset_zero
from .sinks import force_arrays, pandas_metadata, parquet_options

CONNECT_TIMEOUT = 5.0  # seconds to reach a --scheduler before giving up
# Dask's nannies start workers with MALLOC_TRIM_THRESHOLD_=65536, so that freed memory
# goes back to the OS at once.  Setting it (to any value) also turns off glibc's dynamic
# mmap threshold: every array over 128 KiB (a 50,000-row column is 400 KB) is then a
# fresh mmap, page-faulted in and unmapped when freed; about 5,000 page faults a
# dataset part against 20, and 1.4x the time of the whole run (docs/benchmarks.md,
# "Fleets and scaling").  The workers of our own LocalCluster keep glibc's defaults.
WORKER_CONFIG = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}
INSTALL = "pip install 'fsdecouple[dask]'"


def _dask():
    try:
        import dask.dataframe as dd
        import distributed
    except ImportError:
        raise InputError(f"--engine dask needs Dask, which is not installed: {INSTALL}") from None
    return dd, distributed


@contextlib.contextmanager
def _no_interrupt_in_children():
    """Start the cluster's worker processes with SIGINT ignored: a Ctrl-C in the terminal
    reaches the whole process group, and each worker printed its own traceback and leaked
    semaphores (84 lines under the one exit 130).  An ignored signal stays ignored across
    exec, and Python then installs no KeyboardInterrupt handler, so they never see it; the
    client stops them as it unwinds, as after SIGTERM.  A Ctrl-C during the cluster's
    start-up (a second or two) is not seen either; one after it stops the run."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield  # signals are the main thread's: nothing to hold
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _handshake(scheduler: str) -> None:
    """Reach ``scheduler`` and complete distributed's handshake within CONNECT_TIMEOUT, or
    refuse it in one line.  distributed waits for a handshake without a deadline (a
    listener that never answered hung ``apply``), and reads another service's reply as a
    message length (an HTTP server's bytes asked for 3 EiB and ended in a traceback).
    The probe runs on a thread of its own, so a caller's running event loop (a notebook)
    is not in its way."""
    import asyncio
    from concurrent.futures import ThreadPoolExecutor
    from concurrent.futures import TimeoutError as Late

    from distributed import Security
    from distributed.comm import connect

    # the client's own connection arguments (TLS from Dask's config), as Client takes them
    args = Security().get_connection_args("client")

    async def once() -> None:
        comm = await connect(scheduler, timeout=CONNECT_TIMEOUT, **args)
        await comm.close()

    pool = ThreadPoolExecutor(max_workers=1)
    try:
        pool.submit(asyncio.run, asyncio.wait_for(once(), 2 * CONNECT_TIMEOUT)).result(
            timeout=2 * CONNECT_TIMEOUT + 1)
    except (Exception, Late) as err:  # noqa: BLE001 - whatever answered, it is no scheduler
        why = excerpt(err, 200) or type(err).__name__
        raise InputError(f"--scheduler {printable(scheduler)}: cannot connect to a Dask scheduler "
                         f"({why})") from None
    finally:
        pool.shutdown(wait=False)


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None):
    """A client of the cluster at ``scheduler``, or of a new LocalCluster of ``workers`` processes."""
    _, distributed = _dask()
    if scheduler is not None:
        _handshake(scheduler)
        try:
            client = distributed.Client(scheduler, timeout=CONNECT_TIMEOUT, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as err:
            raise InputError(f"--scheduler {printable(scheduler)}: cannot connect to a Dask scheduler "
                             f"({excerpt(err, 200)})") from None
        with client:
            yield client
        return
    import dask

    n = workers or os.cpu_count() or 1
    with dask.config.set(WORKER_CONFIG), _no_interrupt_in_children():
        try:
            cluster = distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                               dashboard_address=":0", silence_logs=logging.CRITICAL)
        except (RuntimeError, OSError, TimeoutError) as err:  # no process may be started here
            raise InputError(f"--engine dask: cannot start a local cluster of {n} worker processes "
                             f"({excerpt(err, 200)}); try --engine local") from None
    with cluster, distributed.Client(cluster, set_as_default=False) as client:
        yield client


def run_dask(spec: ApplySpec, todo: dict[int, tuple[Job, object]], *, scheduler: str | None,
             workers: int | None, finish: Callable[[int, object], None]) -> None:
    """Run each ``todo`` entry (index: (job, staged target)) on Dask; ``finish(i, outcome)``
    as each ends, ``outcome`` being ``(rows, status_counts)`` or a one-line error."""
    _, distributed = _dask()
    run = uuid.uuid4().hex[:8]
    with dask_client(scheduler, workers) as client:
        futures = {}
        for i, (job, target) in todo.items():
            try:
                if job.dataset:
                    fut = client.compute(_dataset_graph(spec, job, target))
                else:
                    fut = client.submit(apply_job, spec, job, target, pure=False,
                                        key=f"fsdecouple-apply-{run}-{i}")
            except FsdecoupleError as err:
                finish(i, str(err))
                continue
            futures[fut] = i
        for fut in distributed.as_completed(list(futures), loop=client.loop):
            i = futures[fut]
            job, target = todo[i]
            try:
                outcome = fut.result()
                if job.dataset:
                    outcome = _count_written(target)
            except FsdecoupleError as err:
                outcome = str(err)
            except distributed.KilledWorker as err:
                outcome = (f"{printable(job.input)}: Dask workers died while decoupling it "
                           f"({excerpt(err, 200)}); nothing written")
            finish(i, outcome)


def _dataset_graph(spec: ApplySpec, job: Job, target):
    """The Dask graph that decouples a Parquet dataset into ``target``: (rows, counts)."""
    import pandas as pd
    import pyarrow as pa

    dd, _ = _dask()
    model = spec.model()
    settings, unit = check_options(model, spec.settings, spec.tare, spec.zero, spec.unit)
    _same_columns(job)
    zero = dataset_zero(spec, job)
    # no hive partitioning: a part under robot=A/ gets no 'robot' column inside its file
    # (the directory names it already, as in apply's local engine, whose parts readers
    # merge whole; Dask's column would be a dictionary whose index width varies by part)
    frame = dd.read_parquet([str(p) for p in job.parts], split_row_groups=False,
                            dtype_backend="pyarrow", index=False, dataset={"partitioning": None})
    try:  # the columns, before any row is read
        frame_outputs(model, frame._meta, settings)
    except InputError as err:
        raise InputError(f"{printable(job.input)}: {err}") from None
    meta = frame._meta.copy()
    for c in _columns(model, meta.columns, spec.interval):
        meta[c] = pd.Series([], dtype=pd.ArrowDtype(pa.float64()))
    meta[STATUS_COLUMN] = pd.Series([], dtype=pd.ArrowDtype(pa.string()))
    factor = load_factor(model.settings.load_unit, unit)
    out = frame.map_partitions(decouple_partition, spec, zero, factor, meta=meta)
    names = [p.name for p in job.parts]
    metadata = {FORCE_UNIT_KEY: unit, OUTPUT_UNIT_KEY: model.settings.output_unit}
    # each part written here, not by to_parquet, whose pandas metadata says
    # double[pyarrow] (and may not be replaced): the local engine's schema, metadata too
    write = out.map_partitions(write_part, str(target), names, metadata,
                               meta=pd.DataFrame({"rows": pd.Series([], dtype="int64")}),
                               align_dataframes=False)
    # the statuses are counted from the parts written (_count_written): a second
    # consumer of the partitions would keep them in memory and stop Dask fusing
    # read, decouple and write into one task per part.  That fusion is the
    # optimizer's last step, which Client.compute skips (dask/distributed#8833):
    # unfused, every part is four tasks whose frames wait in the workers' memory
    # between them, 1.25x the time of the fused graph on the benchmark's 200 parts
    return write.optimize(fuse=True)


def write_part(df, target: str, names: list[str], metadata: dict[str, str], partition_info=None):
    """Write one decoupled partition as ``target/<its input part's name>``, as apply's
    ParquetSink writes a log: the same types, units and pandas metadata."""
    import pandas as pd
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.Table.from_pandas(df, preserve_index=False)
    table = table.replace_schema_metadata({**metadata, b"pandas": pandas_metadata(table.schema)})
    os.makedirs(target, exist_ok=True)
    pq.write_table(table, os.path.join(target, names[partition_info["number"]]),
                   **parquet_options(table.schema))  # encoded as ParquetSink encodes
    return pd.DataFrame({"rows": [len(df)]})


def _same_columns(job: Job) -> None:
    """Every part readable and with the first part's columns (Dask takes the first's schema)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    first = None
    for part in job.parts:
        try:
            names = pq.read_schema(part).names
        except (pa.ArrowInvalid, OSError) as err:
            raise InputError(f"{printable(part)}: not a readable Parquet file ({excerpt(err)})") from None
        if first is None:
            first = names
        elif names != first:
            raise InputError(f"{printable(part)}: columns {', '.join(map(excerpt, names))} differ from "
                             f"the dataset's first part ({', '.join(map(excerpt, first))})")


def _count_written(directory) -> tuple[int, dict[str, int]]:
    """Rows and status counts of a dataset written: its status column, read back.

    A row group whose status statistics have min == max and no nulls holds that
    one status in every row: it is counted from the footer, without reading the
    column (most logs are all ``ok``).  Other row groups are read.
    """
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    from .apply import STATUSES

    counts = dict.fromkeys(STATUSES, 0)
    for part in sorted(os.listdir(directory)):
        with pq.ParquetFile(os.path.join(directory, part)) as pf:
            col = pf.schema_arrow.get_field_index(STATUS_COLUMN)  # flat: the Parquet column too
            mixed = []
            for g in range(pf.metadata.num_row_groups):
                group = pf.metadata.row_group(g)
                stats = group.column(col).statistics
                if (stats is not None and stats.has_min_max and stats.null_count == 0
                        and stats.min == stats.max and stats.min in counts
                        and stats.num_values == group.num_rows):
                    counts[stats.min] += group.num_rows
                else:
                    mixed.append(g)
            if mixed:
                status = pf.read_row_groups(mixed, columns=[STATUS_COLUMN])[STATUS_COLUMN]
                for entry in pc.value_counts(status).to_pylist():
                    counts[entry["values"]] += entry["counts"]
    return sum(counts.values()), counts


def _columns(model, header, interval: float | None) -> tuple[str, ...]:
    """The columns a partition gains, named as single-file ``apply`` names them."""
    forces = force_columns(model.layout.loads, header)
    return forces + (interval_names(forces) if interval is not None else ())


def decouple_partition(df, spec: ApplySpec, zero, factor: float = 1.0):
    """One partition of a dataset: ``decouple_frame``'s arrays, in ``apply``'s Parquet types.

    ``zero``: the dataset's zero (its ``--tare`` rows' mean, or ``--zero``);
    ``factor``: to the force unit asked for (``--unit``).  Forces are Arrow doubles,
    null where a row has none, and ``status`` Arrow strings, as ``apply`` writes them.
    """
    import pandas as pd
    import pyarrow as pa
    import pyarrow.compute as pc

    model = spec.model()
    f, code = frame_forces(model, df, zero=zero, settings=spec.settings, interval=spec.interval)
    if factor != 1.0:
        f = f * factor
    empty = np.isnan(f[:, 0])  # the rows without forces have none at all
    cols = {c: pd.arrays.ArrowExtensionArray(a)
            for c, a in zip(_columns(model, df.columns, spec.interval), force_arrays(f, empty),
                            strict=True)}
    cols[STATUS_COLUMN] = pd.arrays.ArrowExtensionArray(pc.take(STATUS_NAMES, pa.array(code)))
    return df.assign(**cols)
