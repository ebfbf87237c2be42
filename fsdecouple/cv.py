"""The cross-validation protocol of Section 4, against the baselines of Tables 1 and 3.

In each round two repetitions are held out ("test data I" and "test data II") and
the others train every method of :mod:`fsdecouple.baselines` (initial, linear,
rbf-mimo, rbf-siso, svr).  Each is scored by the interference error gamma of eq. (12) on each held-out
repetition's sweeps; optionally also on a combined-load task log with true forces,
with one calibration point moved (Section 4.4, Table 5), and timed (Table 4).
:func:`run_cv` returns the ``cv.json`` document (layout in the README).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from . import __version__
from . import svr as _svr
from .axes import AXES, CHI_NAMES, FORCE_COLUMNS
from .baselines import METHODS, establish, train_all
from .calibration import CalibrationSet, GrossError, load_calibration
from .checks import assumption_checks
from .config import Settings
from .cv_doc import FORMAT, FORMAT_VERSION
from .errors import InputError
from .iotools.calibration import read_task_log
from .linear import fit_omega
from .metrics import interference_error
from .parallel import single_threaded_libraries
from .rbf import B_FACTOR, MSE_GOAL, OUTPUT_LAYER, SPREAD, basic_solution
from .zero import tare_offsets

ROUNDS = 3  # Section 4.1: "the cross validation is repeated three times"
HELD_OUT = 2  # "test data I" and "test data II"
CURVE_POINTS = 201
TIMING_VECTORS = 100  # single-vector decoupling calls timed per repeat (Table 4)


# --- folds ------------------------------------------------------------------------


def parse_folds(text: str) -> list[list[int]]:
    """``"1,2;3,4;5,6"`` -> ``[[1, 2], [3, 4], [5, 6]]``: the held-out repetitions per round."""
    folds = []
    for part in text.split(";"):
        try:
            fold = [int(v) for v in part.split(",")]
        except ValueError:
            raise InputError(
                f"--folds {text!r}: expected repetition numbers, ',' within a round and "
                "';' between rounds, e.g. '1,2;3,4;5,6'"
            ) from None
        folds.append(fold)
    return folds


def default_folds(repetitions: list[int]) -> list[list[int]]:
    """Three rounds holding out consecutive pairs: 1,2; 3,4; 5,6 for six repetitions.

    With fewer than six repetitions the pairs wrap around and shift so that the
    three rounds hold out different pairs (3 repetitions: 1,2; 1,3; 2,3).
    """
    n = len(repetitions)
    folds: list[list[int]] = []
    for start in [*range(0, 2 * n, 2), *range(1, 2 * n, 2)]:
        pair = sorted({repetitions[start % n], repetitions[(start + 1) % n]})
        if pair not in folds:
            folds.append(pair)
        if len(folds) == ROUNDS:
            break
    return folds


def check_folds(folds: list[list[int]], repetitions: list[int]) -> None:
    if len(repetitions) < HELD_OUT + 1:
        raise InputError(
            f"cross-validation needs at least {HELD_OUT + 1} repetitions (two held out, at "
            f"least one to train); the calibration set has {len(repetitions)}"
        )
    have = ", ".join(map(str, repetitions))
    for r, fold in enumerate(folds, start=1):
        if not fold:
            raise InputError(f"--folds: round {r} holds out no repetition")
        for rep in fold:
            if rep not in repetitions:
                raise InputError(
                    f"--folds: round {r} holds out repetition {rep}, which the calibration "
                    f"set does not have (it has {have})"
                )
        if len(set(fold)) != len(fold):
            raise InputError(f"--folds: round {r} names a repetition twice")
        if len(set(fold)) >= len(repetitions):
            raise InputError(f"--folds: round {r} holds out every repetition; none is left to train")


# --- scoring -----------------------------------------------------------------------


def _held_out(calib: CalibrationSet, folds) -> dict[int, tuple]:
    """(voltages, loaded axis, forces) of every held-out repetition, extracted once."""
    out = {}
    for rep in sorted({rep for fold in folds for rep in fold}):
        test = calib.subset([rep])
        out[rep] = (test.voltages, test.points["axis"].to_numpy(), test.forces)
    return out


def _decouple_held_out(tests, folds, models) -> dict[tuple, np.ndarray]:
    """(round, test_set, method) -> decoupled forces of that held-out repetition [N]."""
    return {(r, rep, m): models[(r, m)].decouple(tests[rep][0], rotate=False)
            for r, fold in enumerate(folds, start=1) for rep in fold for m in METHODS}


def _score(tests, forces, settings, points=None) -> list[dict]:
    """gamma (eq. 12) per (round, test_set, method, axis) on the clean held-out data."""
    records = []
    fs = settings.full_scale
    for (r, rep, method), f in forces.items():
        _, axis, loads = tests[rep]
        for a, name in enumerate(AXES):
            records.append({"round": r, "test_set": rep, "method": method, "axis": name,
                            "metric": "gamma",
                            "value": interference_error(f[axis == name], a, fs[a])})
        if points is not None:
            for i in range(len(f)):
                a = AXES.index(axis[i])
                points.append({"round": r, "test_set": rep, "method": method,
                               "axis": axis[i], "load": float(loads[i, a]),
                               **{c: float(v) for c, v in zip(FORCE_COLUMNS, f[i], strict=True)}})
    return records


def _task_records(u, f_true, folds, models, settings) -> list[dict]:
    records = []
    fs = np.asarray(settings.full_scale)
    for r in range(1, len(folds) + 1):
        for method in METHODS:
            err = np.abs(models[(r, method)].decouple(u, rotate=False) - f_true) / fs
            for a, name in enumerate(AXES):
                base = {"round": r, "method": method, "axis": name}
                records.append({**base, "metric": "max_error", "value": float(err[:, a].max())})
                records.append({**base, "metric": "rms_error",
                                "value": float(np.sqrt(np.mean(err[:, a] ** 2)))})
    return records


def _curves(calib, folds, models) -> dict[str, Any]:
    """chi by SVR and by SISO RBF over each chi's calibrated input range, round 1 (Fig. 7)."""
    svr, siso = models[(1, "svr")], models[(1, "rbf-siso")]
    train = [rep for rep in calib.repetitions if rep not in folds[0]]
    chi = {}
    for name in CHI_NAMES:
        lo, hi = svr.chi[name].input_range
        u = np.linspace(lo, hi, CURVE_POINTS)
        chi[name] = {"u": u.tolist(), "svr": svr.chi[name](u).tolist(),
                     "rbf-siso": siso.chi[name](u).tolist()}
    return {"round": 1, "train": train, "test": list(folds[0]), "chi": chi}


def _decouple_seconds(model, vectors, repeats) -> float:
    """Median over repeats of the time to decouple one voltage vector (a (1, 3) call)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for v in vectors:
            model.decouple(v, rotate=False)
        times.append((time.perf_counter() - t0) / len(vectors))
    return float(np.median(times))


# --- the protocol ---------------------------------------------------------------------


def run_cv(
    calib: CalibrationSet | str | Path,
    settings: Settings | None = None,
    *,
    folds: list[list[int]] | None = None,
    task: tuple[str | Path, str | Path] | None = None,
    task_tare: int | None = None,
    gross_error: GrossError | None = None,
    max_gamma: float | None = None,
    workers: int | None = None,
    repeats: int = 1,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """Run the validation protocol of Section 4 and return the ``cv.json`` document.

    Parameters
    ----------
    calib : CalibrationSet or path
        Zero-corrected calibration set with at least three repetitions.
    folds : list of list of int, optional
        Held-out repetitions per round; default :func:`default_folds`.
    task : (voltages, forces) paths, optional
        A combined-load log and its true forces [N] (as ``simulate`` writes).
    task_tare : int, optional
        Zero the task voltages by the mean of their first N rows.
    gross_error : GrossError, optional
        Move one point of the zero-corrected training data (Section 4.4); the
        held-out test data stay clean.
    max_gamma : float, optional
        CI gate: ``gate.passed`` is false when any svr gamma exceeds it.
    workers : int, optional
        Threads for training; default the number of cores; 1 is sequential.
    repeats : int
        Sequential timing passes (Table 4); medians over passes and rounds.
    progress : callable(done, total), optional
        Called as training jobs finish.
    """
    with single_threaded_libraries():
        return _run_cv(calib, settings, folds=folds, task=task, task_tare=task_tare,
                       gross_error=gross_error, max_gamma=max_gamma, workers=workers,
                       repeats=repeats, progress=progress)


def _run_cv(calib, settings, *, folds, task, task_tare, gross_error, max_gamma, workers, repeats,
            progress) -> dict[str, Any]:
    settings = settings or Settings()
    if not isinstance(calib, CalibrationSet):
        calib = load_calibration(calib, settings)
    calib_path = calib.source
    reps = calib.repetitions
    if folds is None:
        if len(reps) < HELD_OUT + 1:
            check_folds([], reps)
        folds = default_folds(reps)
    check_folds(folds, reps)
    if repeats < 1:
        raise InputError(f"--repeats {repeats}: needs at least 1 timing pass")
    if max_gamma is not None and not (np.isfinite(max_gamma) and max_gamma > 0):
        raise InputError(f"--max-gamma {max_gamma}: expected a fraction greater than 0, e.g. 0.016")
    workers = workers or os.cpu_count() or 1
    task_data = None
    if task is not None:
        u_task, f_task = read_task_log(task[0], task[1], settings)
        if task_tare is not None:
            u_task = u_task - tare_offsets(u_task, task_tare)
        task_data = (u_task, f_task)
    gross_calib = None
    if gross_error is not None:
        if gross_error.repetition not in reps:
            raise InputError(
                f"--gross-error: repetition {gross_error.repetition} is not in the calibration "
                f"set (it has {', '.join(map(str, reps))})"
            )
        gross_calib = CalibrationSet(gross_error.apply(calib.points), calib.offsets, calib.files,
                                     calib.skipped, calib.warnings)

    trains = {r: [rep for rep in reps if rep not in fold] for r, fold in enumerate(folds, 1)}
    jobs = [((r, m), m, calib.subset(trains[r])) for r in trains for m in METHODS]
    # with the moved point, only rounds that train on its repetition change
    gross_rounds = [r for r in trains if gross_calib is not None and gross_error.repetition in trains[r]]
    gross_jobs = [(("gross", r, m), m, gross_calib.subset(trains[r]))
                  for r in gross_rounds for m in METHODS]
    # first calls into libsvm and LAPACK, so that neither timing below pays for them
    _svr.fit_svr(np.array([0.0, 1.0]), np.array([0.0, 0.01]), settings.svr)
    basic_solution(np.eye(2), np.ones((2, 1)))
    all_models, wall = train_all(jobs + gross_jobs, settings, workers, progress)
    models = {k: v for k, v in all_models.items() if k[0] != "gross"}

    tests = _held_out(calib, folds)
    forces = _decouple_held_out(tests, folds, models)
    points: list[dict] = []
    records = _score(tests, forces, settings, points)

    # Table 4: a sample of the models established again, sequentially and alone:
    # each method on round 1's training set, `repeats` times.  (That parallel
    # training gives the same models as sequential training is proven by the
    # tests, not re-checked here at the cost of training everything twice.)
    establish_times: dict[str, list[float]] = {m: [] for m in METHODS}
    for _ in range(repeats):
        for _key, method, train in jobs[:len(METHODS)]:  # round 1, one job per method
            t0 = time.perf_counter()
            establish(method, train, settings, workers=1)
            establish_times[method].append(time.perf_counter() - t0)
    # the whole training run done sequentially, estimated from the sample
    count = {m: sum(1 for _, jm, _ in jobs + gross_jobs if jm == m) for m in METHODS}
    sequential = float(sum(np.median(establish_times[m]) * count[m] for m in METHODS))
    first_test = calib.subset(folds[0]).voltages
    vectors = [first_test[i:i + 1] for i in range(min(TIMING_VECTORS, len(first_test)))]
    timing_records = []
    for m in METHODS:
        timing_records.append({"method": m, "metric": "establish_seconds",
                               "value": float(np.median(establish_times[m]))})
        timing_records.append({"method": m, "metric": "decouple_seconds_per_vector",
                               "value": _decouple_seconds(models[(1, m)], vectors, repeats)})

    warnings = list(calib.warnings)
    for r in trains:
        warnings += [f"round {r}: {w}" for w in models[(r, "svr")].warnings
                     if w not in calib.warnings]
    doc: dict[str, Any] = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "fsdecouple_version": __version__,
        "created": datetime.now(UTC).replace(microsecond=0).isoformat(),
        "sensor": settings.sensor,
        "calibration": {"path": calib_path,
                        "files": [{"path": p, "sha256": h} for p, h in calib.files],
                        "repetitions": reps},
        "settings": settings.to_dict(),
        "folds": [list(f) for f in folds],
        "train": [trains[r] for r in trains],
        "methods": list(METHODS),
        "rbf": {"spread": SPREAD, "b": B_FACTOR / SPREAD, "mse_goal": MSE_GOAL,
                "output_layer": OUTPUT_LAYER,
                "input_units": "full-scale outputs" if settings.scaling == "full_scale" else "V",
                "rank": [{"round": r, "method": m, "subject": s, "rank": net.rank,
                          "centres": len(net.centres), "train_mse": net.train_mse}
                         for r in trains for m, s, net in _networks(models, r)]},
        "records": records,
        "task": None,
        "gross_error": None,
        "timing": {
            "records": timing_records,
            "repeats": repeats,
            "establish": "each method fitted alone, sequentially, on round 1's training set, "
                         "once per repeat after the parallel run; median over repeats",
            "decouple": f"{len(vectors)} single-vector calls on round 1's model; median over "
                        "repeats of the mean time per call",
            "parallel": {"workers": workers, "wall_seconds": wall, "sequential_seconds": sequential,
                         "sequential": "estimated: median establish time of each method x its "
                                       "number of training jobs",
                         "speedup": sequential / wall if wall > 0 else None},
        },
        "checks": [{**c.to_dict(), "round": r} for r in trains
                   for c in assumption_checks(models[(r, "svr")])],
        "curves": _curves(calib, folds, models),
        "points": points,
        "gate": None,
        "warnings": warnings,
    }
    if task_data is not None:
        doc["task"] = {"voltages": str(task[0]), "forces": str(task[1]),
                       "rows": int(len(task_data[0])), "tare": task_tare,
                       "records": _task_records(*task_data, folds, models, settings)}
    if gross_calib is not None:
        gmodels = _models_for(all_models, gross=True)
        omega = []
        for r in trains:
            k_clean = fit_omega(calib.subset(trains[r]).points).k
            k_gross = fit_omega(gross_calib.subset(trains[r]).points).k
            for a, name in enumerate(AXES):
                omega.append({"round": r, "axis": name, "k_clean": float(k_clean[a]),
                              "k_gross": float(k_gross[a]), "inverse_clean": float(1 / k_clean[a]),
                              "inverse_gross": float(1 / k_gross[a])})
        doc["gross_error"] = {
            "spec": {"axis": gross_error.axis, "repetition": gross_error.repetition,
                     "point": gross_error.point, "offset": gross_error.offset},
            "placement": "added to the prime voltage of the point in the zero-corrected data; "
                         "training data only, the held-out test data stay clean",
            "rounds_affected": gross_rounds,
            "records": _score(tests, _decouple_held_out(tests, folds, gmodels), settings),
            "omega": omega,
        }
    if max_gamma is not None:
        worst = max(r["value"] for r in records if r["method"] == "svr")
        doc["gate"] = {"max_gamma": max_gamma, "worst": worst, "passed": bool(worst <= max_gamma)}
    return doc


def _models_for(models: dict, gross: bool) -> dict:
    """(round, method) -> model; with ``gross``, the moved-point models where there are any."""
    out = {k: v for k, v in models.items() if k[0] != "gross"}
    if gross:
        out.update({k[1:]: v for k, v in models.items() if k[0] == "gross"})
    return out


def _networks(models, r):
    yield "rbf-mimo", "fx,fy,fz", models[(r, "rbf-mimo")].net
    for name, c in models[(r, "rbf-siso")].chi.items():
        yield "rbf-siso", name, c.net
