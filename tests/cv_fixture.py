"""A cv.json document (layout: /work/spec/cv-json.md) computed with the core alone.

Stand-in for ``fsdecouple cv`` until that command lands: the same three folds of
Section 4 (two held-out repetitions per round), gamma of eq. (12) for the
``initial`` and ``svr`` methods, every held-out point, the assumption checks of
each round's model, the round-1 chi curves, a combined-load block and a gross
error block.  The RBF baselines are left out, so the report must cope with
methods being absent.  Once ``cv`` exists, replace :func:`cv_document` by a call
to it; nothing else in the tests depends on how this document is made.
"""

from __future__ import annotations

import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pandas as pd

from fsdecouple import __version__
from fsdecouple.calibration import GrossError, from_table
from fsdecouple.checks import assumption_checks
from fsdecouple.config import AXES, FORCE_COLUMNS, VOLTAGE_COLUMNS
from fsdecouple.io import calibration_files, read_calibration_table, sha256_file
from fsdecouple.metrics import interference_error
from fsdecouple.model import fit

FOLDS = [[1, 2], [3, 4], [5, 6]]
GROSS = GrossError("x", 3, 5, 0.2)  # a training repetition of round 1, as in Section 4.4


def _methods(model):
    return {
        "initial": lambda u: model.initial_forces(u),
        "svr": lambda u: model.decouple(u, rotate=False),
    }


def _round_records(model, calib, rnd, test_reps, settings, points=None):
    records = []
    for test_set, rep in enumerate(test_reps, start=1):
        held = calib.subset([rep]).points
        for method, f in _methods(model).items():
            for a, axis in enumerate(AXES):
                s = held[held["axis"] == axis]
                forces = f(s[list(VOLTAGE_COLUMNS)].to_numpy())
                g = interference_error(forces, a, settings.full_scale[a])
                records.append({"round": rnd, "test_set": test_set, "method": method,
                                "axis": axis, "metric": "gamma", "value": g})
                if points is not None:
                    loads = s[FORCE_COLUMNS[a]].to_numpy()
                    for load, (fx, fy, fz) in zip(loads, forces, strict=True):
                        points.append({"round": rnd, "test_set": test_set, "method": method,
                                       "axis": axis, "load": float(load), "fx": float(fx),
                                       "fy": float(fy), "fz": float(fz)})
    return records


def _task_records(model, rnd, task_dir, settings, tare=200):
    u = pd.read_csv(task_dir / "task_voltages.csv")[list(VOLTAGE_COLUMNS)].to_numpy()
    truth = pd.read_csv(task_dir / "task_forces.csv")[list(FORCE_COLUMNS)].to_numpy()
    u = u - u[:tare].mean(axis=0)
    out = []
    for method, f in _methods(model).items():
        err = np.abs(f(u) - truth) / np.asarray(settings.full_scale)
        for a, axis in enumerate(AXES):
            out.append({"round": rnd, "method": method, "axis": axis, "metric": "max_error",
                        "value": float(err[:, a].max())})
            out.append({"round": rnd, "method": method, "axis": axis, "metric": "rms_error",
                        "value": float(np.sqrt(np.mean(err[:, a] ** 2)))})
    return out


def cv_document(data_dir: Path, settings) -> dict:
    """The cv.json document for ``data_dir`` (holding calibration/ and the task log)."""
    calib_dir = Path(data_dir) / "calibration"
    table, _ = read_calibration_table(calib_dir, settings)
    files = tuple((str(f), sha256_file(f)) for f in calibration_files(calib_dir))
    calib = from_table(table, settings, files)
    gross_calib = from_table(GROSS.apply(table), settings, files)
    reps = calib.repetitions
    records, points, checks, task, timing = [], [], [], [], []
    gross_records, gross_omega = [], []
    curves = None
    for rnd, test_reps in enumerate(FOLDS, start=1):
        train = [r for r in reps if r not in test_reps]
        t0 = time.perf_counter()
        model = fit(calib.subset(train), settings, workers=1)
        timing.append(time.perf_counter() - t0)
        records += _round_records(model, calib, rnd, test_reps, settings, points)
        checks += [{**c.to_dict(), "round": rnd} for c in assumption_checks(model)]
        task += _task_records(model, rnd, Path(data_dir), settings)
        if rnd == 1:
            curves = {"round": 1, "train": train, "test": list(test_reps), "chi": {}}
            for name, c in model.chi.items():
                u = np.linspace(*c.input_range, 201)
                curves["chi"][name] = {"u": u.tolist(), "svr": c(u).tolist()}
            gross = fit(gross_calib.subset(train), settings, workers=1)
            gross_records += _round_records(gross, calib, rnd, test_reps, settings)
            for a, axis in enumerate(AXES):
                gross_omega.append({
                    "round": rnd, "axis": axis, "k_clean": float(model.k[a]),
                    "k_gross": float(gross.k[a]), "inverse_clean": float(1 / model.k[a]),
                    "inverse_gross": float(1 / gross.k[a]),
                })
    return {
        "format": "fsdecouple.cv",
        "format_version": 1,
        "fsdecouple_version": __version__,
        "created": datetime.now(UTC).replace(microsecond=0).isoformat(),
        "sensor": settings.sensor,
        "calibration": {"path": str(calib_dir), "files": [{"path": p, "sha256": h} for p, h in files],
                        "repetitions": reps},
        "settings": settings.to_dict(),
        "folds": FOLDS,
        "methods": ["initial", "svr"],
        "rbf": None,
        "records": records,
        "task": {"voltages": str(Path(data_dir) / "task_voltages.csv"),
                 "forces": str(Path(data_dir) / "task_forces.csv"),
                 "rows": 3000, "tare": 200, "records": task},
        "gross_error": {"spec": {"axis": GROSS.axis, "repetition": GROSS.repetition,
                                 "point": GROSS.point, "offset": GROSS.offset},
                        "records": gross_records, "omega": gross_omega},
        "timing": {"records": [{"method": "svr", "metric": "establish_seconds",
                                "value": float(np.median(timing))}],
                   "repeats": len(timing), "parallel": None},
        "checks": checks,
        "curves": curves,
        "points": points,
        "gate": None,
    }
