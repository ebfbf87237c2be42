"""The cross-validation protocol of Section 4, against the baselines of Tables 1 and 3.

In each round two repetitions are held out ("test data I" and "test data II") and
the others train every method of :mod:`fsdecouple.fitting.baselines` (initial, linear,
rbf-mimo, rbf-siso, svr).  Each is scored by the interference error gamma of eq. (12) on each held-out
repetition's sweeps; optionally also on a combined-load task log with true forces,
with one calibration point moved (Section 4.4, Table 5), and timed (Table 4).
:func:`run_cv` returns the ``cv.json`` document (layout in docs/cv.md).
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from ..config import Settings
from ..core.metrics import check_max_gamma, interference_error
from ..core.model import FORCE_LIMIT
from ..data.calibration import CalibrationSet, GrossError, load_calibration
from ..data.calibration_csv import read_task_log
from ..data.zero import tare_offsets
from ..errors import InputError, where
from ..fitting import svr as _svr
from ..fitting.baselines import METHODS, establish, train_all
from ..fitting.fit import settled_forces
from ..fitting.linear import fit_omega
from ..fitting.noise import VERDICT_NOISE_FRACTION
from ..fitting.rbf import B_FACTOR, MSE_GOAL, OUTPUT_LAYER, SPREAD, basic_solution
from ..fitting.threads import single_threaded_libraries
from ..schema import refine_argument
from .checks import assumption_checks
from .cv_results import FORMAT, FORMAT_VERSION, REFINED
from .heldout import (
    HeldOutRound,
    check_folds,
    choose_protocol,
    default_folds,
    rounds_for,
)
from .verdict import gamma_records

CURVE_POINTS = 201
TIMING_VECTORS = 100  # single-vector decoupling calls timed per repeat (Table 4)


# --- scoring -----------------------------------------------------------------------


def _held_out(rounds: list[HeldOutRound]) -> dict[tuple, tuple]:
    """(round, test set) -> (outputs, loaded axis, loads) of every held-out set, extracted once."""
    return {(rnd.index, label): (test.voltages, test.points["axis"].to_numpy(), test.forces)
            for rnd in rounds for label, test in rnd.tests}


def _decouple_held_out(tests, models, methods=METHODS) -> dict[tuple, np.ndarray]:
    """(round, test_set, method) -> decoupled forces of that held-out set."""
    return {(r, label, m): models[(r, m)].decouple(tests[(r, label)][0], rotate=False)
            for (r, label) in tests for m in methods}


def _with_refined(models: dict, refine: int, u: np.ndarray) -> dict:
    """``models`` and, for each svr model, the same model refined by ``refine`` steps;
    refused where a refined model does not settle on the calibration outputs ``u``."""
    refined = {(*key[:-1], REFINED): m.refined(refine)
               for key, m in models.items() if key[-1] == "svr"}
    for m in refined.values():
        settled_forces(m, u)
    return {**models, **refined}


def _score(tests, forces, settings, points=None) -> list[dict]:
    """gamma (eq. 12) per (round, test_set, method, axis) on the clean held-out data."""
    records = []
    layout, units = settings.layout, settings.units.loads or None
    for (r, label, method), f in forces.items():
        _, axis, loads = tests[(r, label)]
        for a, name in enumerate(layout.labels):
            if (axis == name).any():
                # decoupled minus applied: a lever arm's own force is no interference
                gamma = interference_error((f - loads)[axis == name], a,
                                           settings.full_scale if units else settings.full_scale[a], units)
                records.append({"round": r, "test_set": label, "method": method, "axis": name,
                                "metric": "gamma", "value": gamma})
        if points is not None:
            for i in range(len(f)):
                a = layout.index(axis[i])
                points.append({"round": r, "test_set": label, "method": method,
                               "axis": axis[i], "load": float(loads[i, a]),
                               **{c: float(v) for c, v in zip(layout.loads, f[i], strict=True)}})
    return records


def _task_records(u, f_true, rounds, models, settings, methods=METHODS) -> list[dict]:
    records = []
    fs = np.asarray(settings.full_scale)
    for r in (rnd.index for rnd in rounds):
        for method in methods:
            err = np.abs(models[(r, method)].decouple(u, rotate=False) - f_true) / fs
            for a, name in enumerate(settings.layout.labels):
                base = {"round": r, "method": method, "axis": name}
                records.append({**base, "metric": "max_error", "value": float(err[:, a].max())})
                records.append({**base, "metric": "rms_error",
                                "value": float(np.sqrt(np.mean(err[:, a] ** 2)))})
    return records


def _curves(rounds, models, protocol) -> dict[str, Any]:
    """chi by SVR and by SISO RBF over each chi's calibrated input range, round 1 (Fig. 7)."""
    first = rounds[0]
    svr, siso = models[(first.index, "svr")], models[(first.index, "rbf-siso")]
    train = first.train.repetitions
    test = [label for label, _ in first.tests] if protocol == "repetitions" else []
    chi = {}
    for name in svr.chi:
        lo, hi = svr.chi[name].input_range
        u = np.linspace(lo, hi, CURVE_POINTS)
        chi[name] = {"u": u.tolist(), "svr": svr.chi[name](u).tolist(),
                     "rbf-siso": siso.chi[name](u).tolist()}
    return {"round": first.index, "train": train, "test": test, "chi": chi}


MAX_REPEATS = 100


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
    protocol: str | None = None,
    tune: bool = False,
    tune_grid=None,
    refine: int | None = None,
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
    protocol : {"repetitions", "levels"}, optional
        What a round holds out (:mod:`fsdecouple.evaluation.heldout`); default: repetitions
        with three or more, else load levels.
    tune : bool
        Choose the SVR settings first, as ``fit --tune`` does on the whole set
        (:mod:`fsdecouple.evaluation.tune`, over ``tune_grid``), and cross-validate with them;
        the record goes to ``doc["tune"]``.
    refine : int, optional
        K >= 1: one more method, ``svr-refined``, the svr models of every round
        decoupled with K steps of the second-order refinement (eqs. 5-6) where the
        ``svr`` row keeps the config's K; ``doc["refine"]`` records K.
    """
    _scipy_before_the_limit()
    with single_threaded_libraries():
        return _run_cv(calib, settings, folds=folds, task=task, task_tare=task_tare,
                       gross_error=gross_error, max_gamma=max_gamma, workers=workers,
                       repeats=repeats, progress=progress, protocol=protocol, tune=tune,
                       tune_grid=tune_grid, refine=refine)


def _scipy_before_the_limit() -> None:
    """Load scipy before cv limits BLAS to one thread, unless its OpenBLAS starts at one.

    scipy ships an OpenBLAS of its own, loaded with the RBF baselines' ``scipy.linalg``.
    Loaded inside the limit while the SVRs train, it kept its threads (threadpoolctl's
    setting does not take then): they cost CPU, and the networks' last digits then
    depended on whether an earlier run had loaded it.  The CLI starts every OpenBLAS at
    one thread (``OPENBLAS_NUM_THREADS``, fsdecouple/cli/__init__.py), so there scipy
    keeps loading beside the SVRs; elsewhere it loads here first (0.4 s, once).
    """
    if "scipy.linalg" not in sys.modules and os.environ.get("OPENBLAS_NUM_THREADS") != "1":
        import scipy.linalg  # noqa: F401


def _refuse_beyond(values: np.ndarray, scale: float, path, columns) -> None:
    """A task log's cell beyond FORCE_LIMIT x ``scale`` (the full scale, or the calibration's
    largest output), refused naming its file, row and column, as apply gives it no forces."""
    bad = np.argwhere(~(np.abs(values) <= FORCE_LIMIT * scale))
    if len(bad):
        i, j = bad[0]
        raise InputError(f"{where(path, int(i) + 2, columns[j])}: {values[i, j]:.6g} is beyond "
                         f"{FORCE_LIMIT:g} x the calibration's full scale ({scale:.6g}): check its units")


def _run_cv(calib, settings, *, folds, task, task_tare, gross_error, max_gamma, workers, repeats,
            progress, protocol, tune=False, tune_grid=None, refine=None) -> dict[str, Any]:
    settings = settings or getattr(calib, "settings", None) or Settings()  # as fit's
    settings.layout.one_output_each("cv")
    if refine is not None:
        refine = refine_argument(refine)
        if refine == 0:
            raise InputError("refine 0: a refined row needs K >= 1 (the svr row keeps the "
                             "config's K)", argument="refine")
    methods = METHODS if not refine else (*METHODS, REFINED)
    if not isinstance(calib, CalibrationSet):
        calib = load_calibration(calib, settings)
    tune_record = None
    if tune:
        from .tune import tune_settings
        settings, tune_record = tune_settings(calib, settings, grid=tune_grid, workers=workers)
    calib_path = calib.source
    reps = calib.repetitions
    protocol = choose_protocol(calib, protocol if protocol is not None or folds is None
                               else "repetitions")
    if protocol in ("levels", "poses") and folds is not None:
        raise InputError(f"folds name held-out repetitions; the {protocol} protocol holds out "
                         f"{'load levels' if protocol == 'levels' else 'poses'}: drop one of "
                         "them", argument="folds")
    if protocol == "repetitions":
        folds = folds if folds is not None else default_folds(reps)
        check_folds(folds, reps)
    rounds = rounds_for(calib, protocol, folds)
    if not 1 <= repeats <= MAX_REPEATS:
        raise InputError(f"{repeats} repeats: expected 1 to {MAX_REPEATS} timing passes",
                         argument="repeats")
    check_max_gamma(max_gamma)
    workers = workers or os.cpu_count() or 1
    task_data = None
    if task is not None:
        u_task, f_task = read_task_log(task[0], task[1], settings)
        # a 1e308 cell is no measurement: its errors would overflow to inf in cv.json
        names = settings.columns  # the files' own column names
        _refuse_beyond(u_task, float(np.abs(calib.voltages).max()), task[0],
                       [names[c] for c in settings.layout.outputs])
        _refuse_beyond(f_task, float(np.max(settings.full_scale)), task[1],
                       [names[c] for c in settings.layout.loads])
        if task_tare is not None:
            u_task = u_task - tare_offsets(u_task, task_tare)
        task_data = (u_task, f_task)
    gross_calib = None
    if gross_error is not None:
        if gross_error.repetition not in reps:
            raise InputError(
                f"gross error: repetition {gross_error.repetition} is not in the calibration "
                f"set (it has {', '.join(map(str, reps))})", argument="gross_error"
            )
        gross_calib = CalibrationSet(gross_error.apply(calib.points, calib.layout), calib.offsets,
                                     calib.files,
                                     calib.skipped, calib.warnings, layout=calib.layout)

    trains = {rnd.index: rnd.train for rnd in rounds}
    jobs = [((r, m), m, train) for r, train in trains.items() for m in METHODS]
    # with the moved point, only rounds that train on it change
    gross_trains = {} if gross_calib is None else {
        rnd.index: rnd.train for rnd in rounds_for(gross_calib, protocol, folds)}
    gross_rounds = [r for r in trains if r in gross_trains
                    and not np.array_equal(gross_trains[r].voltages, trains[r].voltages)]
    gross_jobs = [(("gross", r, m), m, gross_trains[r]) for r in gross_rounds for m in METHODS]
    # first calls into libsvm and LAPACK, so that neither timing below pays for them.  The
    # RBF baselines' scipy (0.4 s to import) loads on a thread of its own while the SVRs,
    # which train_all starts first, train: a job that needs it waits for the import without
    # spending its own thread's time (the parallel timing is thread time); sequential
    # timing is wall time, so there it loads first
    _svr.fit_svr(np.array([0.0, 1.0]), np.array([0.0, 0.01]), settings.svr)
    warm = threading.Thread(target=basic_solution, args=(np.eye(2), np.ones((2, 1))),
                            name="scipy import", daemon=True)
    warm.start()
    if workers <= 1:
        warm.join()
    alone: dict = {}  # each job's time to fit alone (train_all)
    # the rounds' SVRs are solved as the held-out verdict's (the same protocol): to
    # VERDICT_NOISE_FRACTION of sigma, the model to sigma / 2 (fitting/noise.py); a
    # tolerance the user states is obeyed in both
    all_models, wall = train_all(jobs + gross_jobs, settings, workers, progress, seconds=alone,
                                 noise_fraction=VERDICT_NOISE_FRACTION)
    warm.join()
    if refine:
        all_models = _with_refined(all_models, refine, calib.voltages)
    models = {k: v for k, v in all_models.items() if k[0] != "gross"}

    tests = _held_out(rounds)
    forces = _decouple_held_out(tests, models, methods)
    points: list[dict] = []
    records = _score(tests, forces, settings, points)
    # the levels protocol's end points, scored apart (the interior ones are scored above)
    ends = [replace(rnd, tests=()) for rnd in rounds if rnd.end is not None]
    end_records = [{k: v for k, v in r.items() if k != "points"}
                   for r in gamma_records(ends, models, settings, methods)]

    # Table 4: each method's time to establish round 1's model alone: first the
    # training run's own (not fitted twice), then `repeats - 1` more sequential fits.
    # (That parallel training gives the same models as sequential training is
    # proven by the tests, not re-checked here at the cost of training everything twice.)
    establish_times: dict[str, list[float]] = {m: [alone[key]] for key, m, _ in jobs[:len(METHODS)]}
    for _ in range(repeats - 1):
        for _key, method, train in jobs[:len(METHODS)]:  # round 1, one job per method
            t0 = time.perf_counter()
            establish(method, train, settings, workers=1, noise_fraction=VERDICT_NOISE_FRACTION)
            establish_times[method].append(time.perf_counter() - t0)
    # the whole training run done sequentially, estimated from the sample
    count = {m: sum(1 for _, jm, _ in jobs + gross_jobs if jm == m) for m in METHODS}
    sequential = float(sum(np.median(establish_times[m]) * count[m] for m in METHODS))
    first_test = rounds[0].tests[0][1].voltages if rounds[0].tests else rounds[0].train.voltages
    vectors = [first_test[i:i + 1] for i in range(min(TIMING_VECTORS, len(first_test)))]
    timing_records = []
    if refine:
        establish_times[REFINED] = establish_times["svr"]  # the same models: nothing trained
    for m in methods:
        timing_records.append({"method": m, "metric": "establish_seconds",
                               "value": float(np.median(establish_times[m]))})
        timing_records.append({"method": m, "metric": "decouple_seconds_per_vector",
                               "value": _decouple_seconds(models[(1, m)], vectors, repeats)})

    warnings = list(calib.warnings)
    if settings.method is not None:  # the config's method: key is fit's choice, not cv's
        warnings.append(f"config method: {settings.method} not used: cv scores every method "
                        "side by side (fit obeys it)")
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
        "protocol": protocol,
        "folds": [list(f) for f in folds] if protocol == "repetitions"
        else [[label for label, _ in rnd.tests] for rnd in rounds],
        "train": [trains[r].repetitions for r in trains],
        "methods": list(methods),
        "refine": refine or None,
        "rbf": {"spread": SPREAD, "b": B_FACTOR / SPREAD, "mse_goal": MSE_GOAL,
                "output_layer": OUTPUT_LAYER,
                "input_units": "full-scale outputs" if settings.scaling == "full_scale" else "V",
                "rank": [{"round": r, "method": m, "subject": s, "rank": net.rank,
                          "centres": len(net.centres), "train_mse": net.train_mse}
                         for r in trains for m, s, net in _networks(models, r)]},
        "records": records,
        "end_records": end_records,
        "task": None,
        "gross_error": None,
        "timing": {
            "records": timing_records,
            "repeats": repeats,
            "establish": "each method fitted alone on round 1's training set, once per repeat "
                         "(the first: that model's fit in the training run, when parallel the "
                         "CPU time of its thread and of its tasks' pool threads; then "
                         "sequentially); median over repeats",
            "decouple": f"{len(vectors)} single-vector calls on round 1's model; median over "
                        "repeats of the mean time per call",
            "parallel": {"workers": workers, "wall_seconds": wall, "sequential_seconds": sequential,
                         "sequential": "estimated: median establish time of each method x its "
                                       "number of training jobs",
                         "speedup": sequential / wall if wall > 0 else None},
        },
        # a check with no value (NaN: e.g. no sweep of an axis among a round's poses) is
        # not in the document, which is strict JSON
        "checks": [{**c.to_dict(), "round": r} for r in trains
                   for c in assumption_checks(models[(r, "svr")]) if not np.isnan(c.value)],
        "curves": _curves(rounds, models, protocol),
        "points": points,
        "gate": None,
        "warnings": warnings,
    }
    if tune_record is not None:
        doc["tune"] = tune_record
    if task_data is not None:
        doc["task"] = {"voltages": str(task[0]), "forces": str(task[1]),
                       "rows": int(len(task_data[0])), "tare": task_tare,
                       "records": _task_records(*task_data, rounds, models, settings, methods)}
    if gross_calib is not None:
        gmodels = _models_for(all_models, gross=True)
        omega = []
        for r in trains:
            k_clean = fit_omega(trains[r].points, calib.layout).k
            k_gross = fit_omega(gross_trains[r].points, calib.layout).k
            for a, name in enumerate(calib.layout.labels):
                omega.append({"round": r, "axis": name, "k_clean": float(k_clean[a]),
                              "k_gross": float(k_gross[a]), "inverse_clean": float(1 / k_clean[a]),
                              "inverse_gross": float(1 / k_gross[a])})
        doc["gross_error"] = {
            "spec": {"axis": gross_error.axis, "repetition": gross_error.repetition,
                     "point": gross_error.point, "offset": gross_error.offset},
            "placement": "added to the prime voltage of the point in the zero-corrected data; "
                         "training data only, the held-out test data stay clean",
            "rounds_affected": gross_rounds,
            "records": _score(tests, _decouple_held_out(tests, gmodels, methods), settings),
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
    yield "rbf-mimo", ",".join(models[(r, "svr")].layout.loads), models[(r, "rbf-mimo")].net
    for name, c in models[(r, "rbf-siso")].chi.items():
        yield "rbf-siso", name, c.net
