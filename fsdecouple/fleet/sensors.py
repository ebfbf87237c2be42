"""Many sensors in one run: ``fit-many``, the CI re-calibration job in one call.

``SENSORS_DIR`` holds one subdirectory per sensor, named after it, with:

* ``sensor.yaml``, the sensor's config (required);
* its calibration: the subdirectory's ``calibration/`` folder if there is one,
  else the ``.csv`` files of the subdirectory itself.

Each sensor is fitted as ``fit`` fits it (:func:`fsdecouple.evaluation.calibrate.fit`:
the model and its held-out verdict) in a pool of worker processes, and its model
is written atomically to ``MODELS_DIR/<sensor>.json``.  A sensor that cannot be
fitted (no config, bad data) is reported with its one-line error and does not
stop the others; nothing is written for it.  With a baseline directory, every
sensor that has an earlier model there is compared with it
(:func:`fsdecouple.fleet.drift.compare`).
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from ..errors import FsdecoupleError, InputError
from ..files.inputs import natural_key
from ..files.outputs import output_directory

FORMAT = "fsdecouple.fleet"
CONFIG_NAME = "sensor.yaml"
CALIBRATION_DIR = "calibration"
EXECUTORS = ("process", "thread")


@dataclass
class SensorResult:
    """One sensor of a fleet: its model and figures, or the error that stopped it."""

    sensor: str
    directory: str
    model: str | None = None
    k: dict[str, float] | None = None
    units: dict[str, str] | None = None
    method: str | None = None
    worst_gamma: float | None = None  # held-out worst gamma of ``method`` (fraction of F.S.)
    better: str | None = None  # the verdict: svr or linear
    warnings: list[str] = field(default_factory=list)
    drift: dict[str, Any] | None = None
    error: str | None = None
    gate: list[str] = field(default_factory=list)  # why it fails --max-gamma / --max-drift

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class FleetResult:
    """What ``fit-many`` did, one record per sensor in natural order of the names."""

    sensors_dir: str
    models_dir: str
    sensors: list[SensorResult]
    max_gamma: float | None = None
    max_drift: float | None = None
    baseline: str | None = None

    @property
    def failed(self) -> list[SensorResult]:
        """Sensors that could not be fitted (bad input): exit 2."""
        return [s for s in self.sensors if s.error is not None]

    @property
    def gate_failed(self) -> list[SensorResult]:
        """Sensors fitted but failing --max-gamma or --max-drift: exit 1."""
        return [s for s in self.sensors if s.error is None and s.gate]

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT, "sensors_dir": self.sensors_dir, "models_dir": self.models_dir,
            "baseline": self.baseline, "max_gamma": self.max_gamma, "max_drift": self.max_drift,
            "sensors": [s.to_dict() for s in self.sensors],
            "failed": [s.sensor for s in self.failed],
            "gate_failed": [s.sensor for s in self.gate_failed],
        }


def sensor_dirs(sensors_dir: str | Path) -> list[Path]:
    """The sensor subdirectories of ``sensors_dir``, hidden ones skipped, in natural order."""
    root = Path(sensors_dir)
    if not root.is_dir():
        raise InputError(f"{root}: not a directory (expected one subdirectory per sensor)")
    dirs = [p for p in root.iterdir() if p.is_dir() and not p.name.startswith(".")]
    if not dirs:
        raise InputError(f"{root}: holds no sensor subdirectories")
    return sorted(dirs, key=lambda p: natural_key(p.name))


def calibration_path(sensor_dir: Path) -> Path:
    """A sensor's calibration: its ``calibration/`` folder if present, else its own CSVs."""
    sub = sensor_dir / CALIBRATION_DIR
    return sub if sub.is_dir() else sensor_dir


def fit_sensor(sensor_dir: str | Path, models_dir: str | Path, *, method: str | None = None,
               max_gamma: float | None = None, baseline: str | Path | None = None,
               max_drift: float | None = None, force: bool = False,
               workers: int | None = 1) -> SensorResult:
    """Fit one sensor directory and write ``models_dir/<name>.json``; errors are returned.

    Only :class:`~fsdecouple.errors.FsdecoupleError` (bad input) is caught and
    recorded; a bug raises.  Nothing is written for a sensor that fails.
    """
    from ..config import load_config
    from ..core.modelfile import load_model, save_model
    from ..data.calibration import load_calibration
    from ..evaluation.calibrate import fit as calibrate
    from ..evaluation.calibrate import model_slopes, model_units
    from ..files.outputs import check_output
    from .drift import compare

    d = Path(sensor_dir)
    out = Path(models_dir) / f"{d.name}.json"
    result = SensorResult(d.name, str(d))
    try:
        config = d / CONFIG_NAME
        if not config.is_file():
            raise InputError(f"{d}: no {CONFIG_NAME} (each sensor directory needs its config)")
        settings = load_config(config)
        check_output(out, force=force)
        old_path = Path(baseline) / f"{d.name}.json" if baseline is not None else None
        # read before the new model is written: the baseline may be the output directory
        old = load_model(old_path) if old_path is not None and old_path.is_file() else None
        calib = load_calibration(calibration_path(d), settings)
        model = calibrate(calib, settings, method=method, workers=workers)
        if old is not None:
            result.drift = compare(old, model, max_drift=max_drift, en_gate=False)
            result.drift["old"]["model"], result.drift["new"]["model"] = str(old_path), str(out)
        _gates(result, model, max_gamma)
        # a model that fails its gate does not replace the baseline it is judged against:
        # the job's next run would compare with it and pass
        keep = (bool(result.gate) and old is not None
                and os.path.realpath(out) == os.path.realpath(old_path))
        if keep:
            result.drift["new"]["model"] = None  # not written: the file holds the baseline
            result.warnings.append(f"{out} is the baseline and is kept: a sensor that fails a "
                                   "gate does not replace it (fit again without the gate to "
                                   "accept the change)")
        else:
            save_model(model, out, force=force)
    except FsdecoupleError as err:
        result.error = str(err)
        return result
    result.model = None if keep else str(out)
    result.k = model_slopes(model)
    result.units = model_units(model)
    result.method = model.method
    result.warnings = [*model.warnings, *result.warnings]
    return result


def _gates(result: SensorResult, model, max_gamma: float | None) -> None:
    """The held-out verdict's figures into ``result``, and why it fails --max-gamma or
    --max-drift (its drift already compared)."""
    verdict = model.report.verdict
    if verdict is not None:
        result.worst_gamma = verdict["heldout"][model.method]["worst_gamma"]
        result.better = verdict["better"]
    if max_gamma is not None:
        if result.worst_gamma is None:
            result.gate.append("no held-out gamma to check --max-gamma against")
        elif result.worst_gamma > max_gamma:
            result.gate.append(f"held-out worst gamma {100 * result.worst_gamma:.3f} % exceeds "
                               f"--max-gamma {100 * max_gamma:.3f} %")
    if result.drift is not None and result.drift["passed"] is False:
        result.gate.append("drift exceeds --max-drift: " + "; ".join(result.drift["exceeded"]))


def fit_many(sensors_dir: str | Path, models_dir: str | Path, *, method: str | None = None,
             max_gamma: float | None = None, baseline: str | Path | None = None,
             max_drift: float | None = None, force: bool = False, workers: int | None = None,
             executor: str = "process",
             progress: Callable[[int, int], None] | None = None) -> FleetResult:
    """Fit every sensor of ``sensors_dir`` in parallel into ``models_dir/<sensor>.json``.

    Parameters
    ----------
    method : str, optional
        ``svr``, ``linear`` or ``auto``, as ``fit --method``; default: each sensor's
        config's ``method:``, else ``svr``.
    max_gamma : float, optional
        Gate: a sensor fails when its held-out worst gamma (eq. 12, of the method
        its model decouples with) exceeds this fraction of full scale.
    baseline : path, optional
        Directory of earlier models ``<sensor>.json``: each sensor that has one is
        compared with it (drift); ``max_drift`` [%] gates the drift.
    workers : int, optional
        Sensors fitted at once; default: the cores (at most the sensors).
    executor : str
        ``process`` (default: each sensor fits in a worker process, one thread
        each) or ``thread``.
    progress : callable, optional
        Called as ``progress(done, total)`` in sensors.
    """
    from ..core.metrics import check_max_gamma
    from ..evaluation.calibrate import FIT_METHODS
    from .drift import check_max_drift

    check_max_gamma(max_gamma)
    check_max_drift(max_drift)
    if method is not None and method not in FIT_METHODS:
        raise InputError(f"--method {method!r}: expected one of {', '.join(FIT_METHODS)}")
    if executor not in EXECUTORS:
        raise InputError(f"executor {executor!r}: expected one of {', '.join(EXECUTORS)}")
    if workers is not None and workers < 1:
        raise InputError(f"--workers {workers}: expected a whole number >= 1")
    if max_drift is not None and baseline is None:
        raise InputError("--max-drift gates the drift against --baseline; give --baseline")
    dirs = sensor_dirs(sensors_dir)
    out = Path(models_dir)
    for d in dirs:
        if out.resolve() == d.resolve() or d.resolve() in out.resolve().parents:
            raise InputError(f"{out}: is inside the sensor directory {d}; write the models elsewhere")
    if baseline is not None and not Path(baseline).is_dir():
        raise InputError(f"--baseline {baseline}: not a directory of earlier models")
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: is a file, expected a directory for the models")
    if not out.parent.is_dir():
        raise InputError(f"{out}: directory {out.parent} does not exist")
    made = not out.exists()
    output_directory(out)

    workers = min(workers or os.cpu_count() or 1, len(dirs))
    kw = dict(method=method, max_gamma=max_gamma, baseline=baseline, max_drift=max_drift,
              force=force, workers=1)
    results: dict[str, SensorResult] = {}
    if executor == "thread":
        from ..fitting import svr  # noqa: F401 (libsvm loads on this thread, before the pool: svr.py)
    pool = ProcessPoolExecutor if executor == "process" else ThreadPoolExecutor
    ex = pool(workers)
    try:
        futures = [ex.submit(fit_sensor, d, out, **kw) for d in dirs]
        for n, fut in enumerate(as_completed(futures), 1):
            r = fut.result()
            results[r.sensor] = r
            if progress is not None:
                progress(n, len(dirs))
    except BaseException:  # SIGTERM, Ctrl-C, a bug: stop the workers too, now
        _stop(ex)
        if made:  # the directory this run made, if no model was written into it
            with contextlib.suppress(OSError):
                out.rmdir()
        raise
    ex.shutdown()
    if made:  # every sensor failed: no empty directory left behind, as apply leaves none
        with contextlib.suppress(OSError):
            out.rmdir()  # only while empty
    return FleetResult(str(sensors_dir), str(models_dir), [results[d.name] for d in dirs],
                       max_gamma, max_drift, None if baseline is None else str(baseline))


def _stop(ex) -> None:
    """Cancel what has not started and end the worker processes.  Each unwinds its sensor
    on SIGTERM (temporary files removed) instead of finishing it; as the pool's worker
    loop then waits for more work, what still runs a moment later is killed."""
    processes = list((getattr(ex, "_processes", None) or {}).values())
    ex.shutdown(wait=False, cancel_futures=True)
    for p in processes:
        with contextlib.suppress(OSError, ValueError):
            p.terminate()
    deadline = time.monotonic() + STOP_GRACE
    for p in processes:
        p.join(timeout=max(0.0, deadline - time.monotonic()))
        if p.is_alive():
            p.kill()
            p.join(timeout=1)


STOP_GRACE = 2.0  # seconds for a worker to unwind after SIGTERM
