"""One log of a many-log ``apply``: what a worker runs, whatever the engine.

A :class:`Job` is one input (a log file, or a Parquet dataset directory and its
parts) and where its output goes; an :class:`ApplySpec` is the rest of the
command (the model by its path, config, tare, zero, unit), picklable so that a
Dask worker gets it.  :func:`apply_job` is the per-log core of every engine:
single-file ``apply`` (:func:`fsdecouple.logs.apply.apply_file`), so the bytes are the
same whichever engine ran it.
"""

from __future__ import annotations

import functools
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config import Settings


@dataclass(frozen=True)
class Job:
    """One input: a log file, or a Parquet dataset directory with its ``parts``."""

    input: Path
    rel: Path  # its output, relative to OUT_DIR
    parts: tuple[Path, ...] = ()
    problem: str | None = None  # why a name found in a directory cannot be read as a log

    @property
    def dataset(self) -> bool:
        return bool(self.parts)


@dataclass(frozen=True)
class ApplySpec:
    """Everything a worker needs to decouple a log, picklable (the model by its path)."""

    model_path: str
    refine: int | None = None
    settings: Settings | None = None
    tare: int | None = None
    zero: tuple[float, ...] | None = None
    unit: str | None = None
    round_trip: bool = False
    threads: int | None = None  # threads per log (apply_file's workers)
    interval: float | None = None  # --interval P: the _lo/_hi columns (core/intervals.py)

    def model(self):
        return _load(self.model_path, self.refine)


@functools.lru_cache(maxsize=4)
def _load(path: str, refine: int | None):
    # once per process: a Dask worker decouples many logs with one model
    from ..core.modelfile import load_model

    model = load_model(path)
    return model if refine is None else model.refined(refine)


def apply_job(spec: ApplySpec, job: Job, target: str | Path) -> tuple[int, dict[str, int]]:
    """Decouple one input into ``target`` (a file, or a directory for a dataset).

    A dataset's parts are decoupled ``spec.threads`` at a time with the dataset's zero
    (:func:`dataset_zero`), each into ``target/<part name>``.
    Returns the rows and status counts.
    """
    from .apply import STATUSES, apply_file

    model, target = spec.model(), Path(target)
    kw = dict(settings=spec.settings, unit=spec.unit, round_trip=spec.round_trip,
              workers=spec.threads, interval=spec.interval)
    if not job.dataset:
        s = apply_file(model, job.input, target, tare=spec.tare, zero=spec.zero, **kw)
        return s.rows, s.status_counts
    zero = dataset_zero(spec, job)
    target.mkdir()
    rows, counts = 0, dict.fromkeys(STATUSES, 0)
    # parts at once rather than blocks at once: a part is often one block
    kw["workers"] = 1
    with ThreadPoolExecutor(spec.threads or 1) as pool:
        for s in pool.map(lambda part: apply_file(model, part, target / part.name, zero=zero,
                                                  **kw), job.parts):
            rows += s.rows
            counts = {k: counts[k] + s.status_counts[k] for k in counts}
    return rows, counts


def dataset_zero(spec: ApplySpec, job: Job):
    """The zero removed from a dataset: ``--zero``, or the mean of its first ``--tare`` rows."""
    from .apply import check_options, read_tare
    from .reader import parquet_blocks

    if spec.tare is None:
        return spec.zero
    model = spec.model()
    settings, _ = check_options(model, spec.settings, spec.tare, None, spec.unit)
    outputs = model.layout.outputs
    names = [settings.columns[c] for c in outputs]
    scale = np.array([settings.scale[c] for c in outputs])
    blocks = (block for part in job.parts  # as apply reads a log's tare rows: the same doubles
              for block in parquet_blocks(part, names, settings, chunk_rows=spec.tare))
    return tuple(read_tare(blocks, scale, spec.tare, job.input)[0])
