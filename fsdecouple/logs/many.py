"""Apply a model to many logs: ``apply MODEL INPUT... -o OUT_DIR/``, on one machine or on Dask.

Which logs (:func:`find_jobs`):

* a file, several files, a glob (``'logs/**/*.csv'``) or a directory;
* a directory means every ``.csv``, ``.parquet`` and ``.pq`` file under it,
  recursively, hidden files and directories skipped;
* a directory of Parquet *parts* is one partitioned dataset, read and written as a
  whole (:func:`is_dataset`): its name ends in ``.parquet``, or it holds
  ``_metadata``, ``_common_metadata`` or ``_SUCCESS``, or every Parquet file in it
  is named ``part*`` (Dask's ``part.0.parquet``, Spark's and pyarrow's
  ``part-00000...``).  Its parts are the Parquet files directly in it.

Where the outputs go: each log's output is written under ``OUT_DIR`` at the log's
path relative to the directory given, or to the common parent of the files given
(a dataset given itself: ``OUT_DIR/<its name>/``), in the log's own format.

Each log is decoupled as single-file ``apply`` does it (:func:`fsdecouple.logs.apply.apply_file`,
the same bytes), ``--tare`` taken per log (a dataset's first rows, parts in natural
order, for a dataset).  Outputs are first written to a hidden staging directory
inside ``OUT_DIR`` and moved into place when finished, so a log that fails (bad
input, a worker killed for good) leaves nothing behind, and does not stop the
others.  The engines: ``local`` (threads, several logs at once)
and ``dask`` (:mod:`fsdecouple.logs.dask_engine`).
"""

from __future__ import annotations

import contextlib
import glob
import os
import shutil
import stat
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ..config import Settings
from ..errors import FsdecoupleError, InputError, printable
from ..files.inputs import natural_key
from ..files.outputs import names_a_directory, output_directory, place, place_directory
from ..schema import unused_warning
from .apply import MAX_WORKERS
from .jobs import ApplySpec, Job, apply_job
from .reader import PARQUET_SUFFIXES, is_parquet

FORMAT = "fsdecouple.apply_many"
ENGINES = ("local", "dask")
LOG_SUFFIXES = (".csv", *PARQUET_SUFFIXES)
DATASET_MARKERS = ("_metadata", "_common_metadata", "_SUCCESS")
STAGE_PREFIX = ".fsdecouple-apply-"


@dataclass
class FileResult:
    """One input's outcome: its output, rows and status counts, or its one-line error."""

    input: str
    output: str
    rows: int = 0
    status_counts: dict[str, int] | None = None
    error: str | None = None


@dataclass
class BatchResult:
    engine: str
    output_dir: str
    files: list[FileResult] = field(default_factory=list)
    force_unit: str | None = None
    warnings: list[str] = field(default_factory=list)  # config keys not used (schema.unused_warning)

    @property
    def failed(self) -> list[FileResult]:
        return [f for f in self.files if f.error is not None]

    def to_dict(self) -> dict[str, Any]:
        return {"format": FORMAT, "engine": self.engine, "output_dir": self.output_dir,
                "force_unit": self.force_unit, "files": [vars(f) for f in self.files],
                "failed": [f.input for f in self.failed], "warnings": self.warnings}


# --- which inputs ------------------------------------------------------------------


def is_batch(inputs, output) -> bool:
    """Whether ``apply INPUT... -o OUTPUT`` is the many-log form (else single-file ``apply``).

    Many logs: more than one input, a directory or a glob as input, or an output
    that is a directory or ends with ``/`` (or ``/.``).
    """
    if len(inputs) != 1:
        return True
    given, out = str(inputs[0]), str(output)
    if given == "-":
        return False
    return (Path(given).is_dir() or (not Path(given).exists() and glob.has_magic(given))
            or names_a_directory(out) or Path(out).is_dir())


def is_dataset(directory: Path) -> bool:
    """A directory of Parquet parts, read and written as one partitioned dataset."""
    if directory.suffix.lower() in PARQUET_SUFFIXES:
        return True
    names = [p.name for p in directory.iterdir()] if directory.is_dir() else []
    if any(m in names for m in DATASET_MARKERS):
        return True
    parts = [n for n in names if Path(n).suffix.lower() in PARQUET_SUFFIXES]
    return bool(parts) and all(n.lower().startswith("part") for n in parts)


def _parts(directory: Path) -> tuple[Path, ...]:
    parts = sorted((p for p in directory.iterdir() if p.is_file() and is_parquet(p)
                    and not p.name.startswith((".", "_"))), key=lambda p: natural_key(p.name))
    if not parts:
        raise InputError(f"{printable(directory)}: a Parquet dataset directory with no part files")
    return tuple(parts)


def _walk(directory: Path, base: Path) -> list[Job]:
    """The logs under ``directory``, outputs relative to ``base``; datasets as one job each."""
    if is_dataset(directory):
        return [Job(directory, directory.relative_to(base), _parts(directory))]
    jobs = []
    for p in sorted(directory.iterdir(), key=lambda p: natural_key(p.name)):
        if p.name.startswith("."):
            continue
        named_like_a_log = p.suffix.lower() in LOG_SUFFIXES
        if p.is_dir():
            inside = _walk(p, base)
            if named_like_a_log and not inside:
                inside = [Job(p, p.relative_to(base), problem="a directory named like a log, "
                                                              "holding none")]
            jobs += inside
        elif named_like_a_log:  # never passed over in silence: listed as failed if unreadable
            jobs.append(Job(p, p.relative_to(base), problem=_not_a_log(p)))
    return jobs


def _not_a_log(p: Path) -> str | None:
    """Why an entry named like a log cannot be read as one (None: a regular file)."""
    if p.is_file():
        return None
    if p.is_symlink() and not p.exists():
        return "a symbolic link to nothing"
    mode = p.stat().st_mode
    kind = "a FIFO" if stat.S_ISFIFO(mode) else "a socket" if stat.S_ISSOCK(mode) else "a device"
    return f"{kind}, not a regular file (a directory's logs must be files)"


def _real(path) -> Path:
    """``path`` resolved; a symbolic link loop (``loop.csv -> loop.csv``) stays as it is,
    where Path.resolve raised RuntimeError (a traceback) before the log could be listed."""
    return Path(os.path.realpath(path))


def find_jobs(inputs) -> tuple[list[Job], list[Path]]:
    """The logs named by ``inputs`` and where their outputs go; and the directories given.

    Raises :class:`InputError` for a path that does not exist, a glob or a
    directory that matches no log, and two inputs that would have one output.
    """
    jobs: list[Job] = []
    loose: list[Path] = []  # files, and directories a glob matched: relative to their parent
    dirs: list[Path] = []
    for given in map(str, inputs):
        if Path(given).is_dir():
            d = Path(given)
            dirs.append(d)
            found = _walk(d, d.parent if is_dataset(d) else d)
            if not found:
                raise InputError(f"{printable(given)}: a directory with no .csv or .parquet log")
            jobs += found
        elif Path(given).exists():
            loose.append(Path(given))
        elif glob.has_magic(given):
            matched = [Path(m) for m in sorted(glob.glob(given, recursive=True), key=natural_key)
                       if Path(m).is_dir() or Path(m).suffix.lower() in LOG_SUFFIXES]
            if not matched:
                raise InputError(f"{printable(given)}: matches no .csv or .parquet log")
            loose += matched
            dirs += [m for m in matched if m.is_dir()]
        else:
            raise InputError(f"{printable(given)}: file not found")
    # /dev/stdin and <(...) resolve to no file ("pipe:[...]"): named as given, outside the base
    piped = [p for p in loose if not _real(p).exists()]
    named = [_real(p).parent for p in loose if p not in piped]
    base = Path(os.path.commonpath(named)) if named else None
    for p in loose:
        if p in piped:
            jobs.append(Job(p, Path(p.name if p.suffix.lower() in LOG_SUFFIXES else f"{p.name}.csv")))
        else:
            found = _walk(p, base) if p.is_dir() else [Job(p, _real(p).relative_to(base))]
            if p.is_dir() and not found:
                raise InputError(f"{printable(p)}: a directory with no .csv or .parquet log")
            jobs += found
    unique: dict[Path, Job] = {}
    for job in jobs:
        unique.setdefault(_real(job.input), job)
    jobs = list(unique.values())
    seen: dict[Path, Job] = {}
    for job in jobs:
        if job.rel in seen:
            raise InputError(f"{printable(job.input)} and {printable(seen[job.rel].input)} would "
                             f"both be written to {printable(job.rel)}; give them separately")
        seen[job.rel] = job
    return jobs, dirs


def check_out_dir(out_dir: Path, jobs: list[Job], dirs: list[Path], others=()) -> None:
    """Refuse an output directory that is, or lies inside, an input; and outputs onto inputs."""
    out = _real(out_dir)
    for d in [*dirs, *(j.input for j in jobs if j.dataset)]:
        if out == _real(d) or _real(d) in out.parents:
            raise InputError(f"{printable(out_dir)}: is the input directory {printable(d)} or inside "
                             "it; write the outputs elsewhere")
    inputs = {_real(p) for j in jobs for p in (j.input, *j.parts)} | {_real(p) for p in others}
    if out in inputs:
        raise InputError(f"{printable(out_dir)}: is one of the inputs; write the outputs elsewhere")
    for job in jobs:
        if _real(out / job.rel) in inputs:
            raise InputError(f"{printable(out_dir / job.rel)}: is also an input file; write the "
                             "outputs elsewhere")
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(f"{printable(out_dir)}: is a file, expected a directory for the outputs")
    parent = out_dir.parent if str(out_dir.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"{printable(out_dir)}: directory {printable(parent)} does not exist")


# --- many logs ------------------------------------------------------------------------


def apply_many(model_path: str | Path, inputs, out_dir: str | Path, *, engine: str = "local",
               scheduler: str | None = None, workers: int | None = None,
               settings: Settings | None = None, config: str | Path | None = None,
               tare: int | None = None, zero=None, unit: str | None = None,
               refine: int | None = None, round_trip: bool = False, force: bool = False,
               interval: float | None = None,
               progress: Callable[[int, int], None] | None = None) -> BatchResult:
    """Decouple every log named by ``inputs`` into ``out_dir``; per-log errors are recorded.

    Parameters
    ----------
    engine : str
        ``local`` (``workers`` threads, as many logs at once) or ``dask``
        (``scheduler``: a Dask scheduler address; none starts a LocalCluster of
        ``workers`` processes).
    settings, tare, zero, unit, refine, round_trip, interval
        As single-file ``apply`` (:func:`fsdecouple.logs.apply.apply_file`); ``tare`` per log.
    progress : callable, optional
        Called as ``progress(done, total)`` in logs.

    Notes
    -----
    Only :class:`~fsdecouple.errors.FsdecoupleError` of a log is caught and
    recorded (a bug raises); bad arguments raise before any log is read.
    """
    from ..evaluation.intervals import half_widths
    from .apply import check_options

    if engine not in ENGINES:
        raise InputError(f"--engine {engine!r}: expected one of {', '.join(ENGINES)}")
    if workers is not None and workers < 1:
        raise InputError(f"--workers {workers}: expected a whole number >= 1")
    if scheduler is not None and engine != "dask":
        raise InputError("--scheduler is the address of a Dask cluster: give --engine dask too")
    model = ApplySpec(str(model_path), refine).model()  # a bad file or K refused here, once
    _, force_unit = check_options(model, settings, tare, zero, unit)
    if interval is not None:
        half_widths(model, interval)  # a bad P, or a model without held-out residuals
    jobs, dirs = find_jobs(inputs)
    out = Path(out_dir)
    check_out_dir(out, jobs, dirs, [model_path, *([config] if config is not None else [])])
    spec = ApplySpec(str(Path(model_path).resolve()), refine, settings, tare,
                     None if zero is None else tuple(float(v) for v in zero), unit, round_trip,
                     1, interval)
    results = [FileResult(str(j.input), str(out / j.rel)) for j in jobs]
    todo = []
    for i, job in enumerate(jobs):
        if job.problem is not None:
            results[i].error = f"{printable(job.input)}: {job.problem}; not decoupled"
        elif (out / job.rel).exists() and not force:
            results[i].error = f"{printable(out / job.rel)}: already exists; pass --force to overwrite it"
        else:
            todo.append(i)
    made = not out.exists()
    output_directory(out)
    try:
        stage = Path(tempfile.mkdtemp(prefix=STAGE_PREFIX, dir=out))
    except OSError as err:
        raise InputError(f"{printable(out)}: cannot write into it ({err.strerror})") from None
    done = [0]

    def finish(i: int, outcome) -> None:
        # the log is finished (or failed): move it into place, from this process only
        if isinstance(outcome, str):
            results[i].error = outcome
        else:
            results[i].rows, results[i].status_counts = outcome
            try:
                _place(_staged(stage, i, jobs[i]), out / jobs[i].rel, jobs[i].dataset, force)
            except FsdecoupleError as err:
                results[i].error = str(err)
        done[0] += 1
        if progress is not None:
            progress(done[0], len(todo))

    try:
        if engine == "local":
            _run_local(spec, {i: (jobs[i], _staged(stage, i, jobs[i])) for i in todo}, workers,
                       finish)
        else:
            from .dask_engine import run_dask

            run_dask(spec, {i: (jobs[i], _staged(stage, i, jobs[i])) for i in todo},
                     scheduler=scheduler, workers=workers, finish=finish)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
        if made:
            with contextlib.suppress(OSError):
                out.rmdir()  # only if nothing was written
    notes = unused_warning(settings, model.settings) if settings is not None else []
    return BatchResult(engine, str(out_dir), results, force_unit, notes)


def _run_local(spec: ApplySpec, todo: dict[int, tuple[Job, Path]], workers: int | None,
               finish: Callable[[int, object], None]) -> None:
    """Several logs at once on threads: a log of one block (50,000 rows) has no parallelism
    of its own.  ``workers`` threads in all: as many logs at once, up to the logs; a log
    alone gets them all for its blocks."""
    from concurrent.futures import ThreadPoolExecutor, as_completed

    cores = workers or min(MAX_WORKERS, os.cpu_count() or 1)
    at_once = max(1, min(cores, len(todo)))
    spec = replace(spec, threads=max(1, cores // at_once))

    def one(i: int):
        job, target = todo[i]
        try:
            return i, apply_job(spec, job, target)
        except FsdecoupleError as err:
            return i, str(err)

    with ThreadPoolExecutor(at_once) as pool:
        futures = [pool.submit(one, i) for i in todo]
        try:
            for fut in as_completed(futures):
                finish(*fut.result())
        except BaseException:
            for fut in futures:  # Ctrl-C: start no other log; those running finish
                fut.cancel()
            raise


def _staged(stage: Path, i: int, job: Job) -> Path:
    return stage / (f"{i}" if job.dataset else f"{i}{job.input.suffix}")


def _place(staged: Path, target: Path, dataset: bool, force: bool) -> None:
    target.parent.mkdir(parents=True, exist_ok=True)
    if dataset:
        place_directory(staged, target, force=force)
    else:
        place(str(staged), target, force=force)
