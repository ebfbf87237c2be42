"""An honest verdict: does the coupling error model beat the calibration matrix on held-out data?

In-sample gamma (eq. 12) of a model fitted on the very points it is scored on says
little on a small calibration (an SVR with C = 1000 and a tiny epsilon goes
through every point).  The verdict scores three methods on points they were not
fitted on, by the held-out protocol of :mod:`fsdecouple.evaluation.heldout`:

* ``initial``: no coupling correction, f = omega^-1(u) (eq. 13);
* ``linear``: the least-squares calibration matrix (Section 1), the industry's tool;
* ``svr``: the coupling error model with eps-SVRs (eq. 11, Table 2).

Each method's figure is its worst held-out gamma over rounds and loaded axes; with
the levels protocol the end points (extrapolation) are reported apart.  On rig rows
that load several components (:mod:`fsdecouple.fitting.joint`) the verdict compares the
worst component's RMS error of decoupled minus applied loads over every held-out
point instead (``worst_rms``, end points included): eq. (12) counts the off-axis
components only, so it cannot see a component's error in its own load, which is
where a rig's readings bend most (issue 22).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..config import Settings
from ..core.metrics import interference_error, pct
from ..data.calibration import CalibrationSet
from ..fitting.baselines import train_all
from ..fitting.joint import multi_load
from ..fitting.noise import VERDICT_NOISE_FRACTION
from .budget import heldout_predictions
from .heldout import HeldOutRound, choose_protocol, rounds_for
from .intervals import centre

VERDICT_METHODS = ("initial", "linear", "svr")


def gamma_records(rounds: list[HeldOutRound], models: dict, settings: Settings,
                  methods=VERDICT_METHODS) -> list[dict[str, Any]]:
    """gamma (eq. 12) per (round, test set, method, axis), interior and end points apart."""
    fs, labels, units = settings.full_scale, settings.layout.labels, settings.units.loads or None
    records = []
    for rnd in rounds:
        groups = [(label, test, "interior") for label, test in rnd.tests]
        if rnd.end is not None:
            groups.append((rnd.index, rnd.end, "end"))
        for label, test, points in groups:
            axis = test.points["axis"].to_numpy()
            for m in methods:
                # decoupled minus applied: a lever arm's own force is no interference
                f = models[(rnd.index, m)].decouple(test.voltages, rotate=False) - test.forces
                for a, name in enumerate(labels):
                    if (axis == name).any():
                        gamma = interference_error(f[axis == name], a, fs if units else fs[a], units)
                        records.append({"round": rnd.index, "test_set": label, "method": m,
                                        "axis": name, "points": points, "metric": "gamma",
                                        "value": gamma})
    return records


def heldout_rms(rounds: list[HeldOutRound], models: dict, settings: Settings,
                methods=VERDICT_METHODS) -> dict[str, float]:
    """Per method, the worst component's RMS of decoupled minus applied loads [fraction of
    F.S.] over every held-out point, end points included (issue 22's rig figure)."""
    fs = np.asarray(settings.full_scale, dtype=float)
    out = {}
    for m in methods:
        errors = [(models[(rnd.index, m)].decouple(test.voltages, rotate=False) - test.forces) / fs
                  for rnd in rounds
                  for test in [t for _, t in rnd.tests] + ([rnd.end] if rnd.end is not None else [])]
        e = np.concatenate(errors)
        out[m] = float(np.sqrt((e ** 2).mean(axis=0)).max()) if len(e) else None
    return out


def heldout_verdict(calib: CalibrationSet, settings: Settings, *, protocol: str | None = None,
                    workers: int | None = None) -> dict[str, Any]:
    """Score initial, linear and svr by the held-out protocol; the ``verdict`` document."""
    protocol = choose_protocol(calib, protocol)
    rounds = rounds_for(calib, protocol)
    jobs = [((r.index, m), m, r.train) for r in rounds for m in VERDICT_METHODS]
    # the rounds' SVRs are solved to VERDICT_NOISE_FRACTION of sigma (noise.py: sigma, the
    # model sigma / 2)
    # the rounds' SVRs are tasks on one pool (train_all): the last round to start then
    # does not train alone on one core while the others idle (fit: its SVRs are 90 % of the CPU)
    models, _ = train_all(jobs, settings, workers or 1, None, tables=False,
                          noise_fraction=VERDICT_NOISE_FRACTION)
    records = gamma_records(rounds, models, settings)
    heldout = {}
    for m in VERDICT_METHODS:
        inner = [r for r in records if r["method"] == m and r["points"] == "interior"]
        end = [r for r in records if r["method"] == m and r["points"] == "end"]
        heldout[m] = {
            "worst_gamma": max((r["value"] for r in inner), default=None),
            "worst_gamma_end": max((r["value"] for r in end), default=None),
            "gamma": {a: max(r["value"] for r in inner if r["axis"] == a)
                      for a in settings.layout.labels if any(r["axis"] == a for r in inner)},
        }
    for m, rms in heldout_rms(rounds, models, settings).items():
        heldout[m]["worst_rms"] = rms
    # the held-out forces of each method, for the certificate's budget and intervals
    predictions = {m: heldout_predictions(rounds, models, m) for m in ("svr", "linear")}
    # and where apply --interval centres its intervals (refined: core/intervals.py)
    centred = {m: heldout_predictions(rounds, models, m, centre)[1] for m in ("svr", "linear")}
    trained = float(np.mean([len(r.train.repetitions) for r in rounds]))
    # rig rows (several loads a row, fitting/joint.py): judged by every component's error,
    # for eq. (12) sees no error of a component in its own load; the paper's sweeps by gamma
    figure = "worst_rms" if multi_load(calib.forces) else "worst_gamma"
    svr, linear = heldout["svr"][figure], heldout["linear"][figure]
    better = "svr" if linear is None or (svr is not None and svr <= linear) else "linear"
    return {
        "protocol": protocol,
        "figure": figure,
        "rounds": len(rounds),
        "points": {"levels": "held-out interior points; end points (levels protocol) apart, "
                             "as worst_gamma_end",
                   "poses": "held-out poses, every fifth in file order"}.get(
                       protocol, "held-out repetitions"),
        "heldout": heldout,
        "better": better,
        "records": records,
        "predictions": predictions,
        "centred": centred,
        "trained": trained,
    }


def choose(verdict: dict[str, Any], method: str) -> str:
    """The method a model decouples with: ``svr`` or ``linear`` as asked, or the better for ``auto``."""
    return verdict["better"] if method == "auto" else method


def verdict_line(verdict: dict[str, Any]) -> str:
    """One line a technician can act on."""
    h = verdict["heldout"]
    figure = verdict.get("figure", "worst_gamma")
    svr, linear = h["svr"][figure], h["linear"][figure]
    what = "worst gamma" if figure == "worst_gamma" else "worst component's RMS error"
    where = (f"held-out {what} ({verdict['protocol']} protocol, {verdict['rounds']} rounds): "
             f"svr {pct(svr)}, calibration matrix {pct(linear)}, initial {pct(h['initial'][figure])}")
    if verdict["better"] == "svr":
        return f"verdict: the coupling error model generalizes better than the calibration matrix; {where}"
    return (f"verdict: the least-squares calibration matrix generalizes better than the coupling "
            f"error model on this data; {where}")


def verdict_warning(verdict: dict[str, Any], method: str) -> str | None:
    """A warning when the chosen method is the worse one on held-out data."""
    if method == "svr" and verdict["better"] == "linear":
        h, figure = verdict["heldout"], verdict.get("figure", "worst_gamma")
        what = "worst gamma" if figure == "worst_gamma" else "worst component's RMS error"
        return (f"the calibration matrix generalizes better than the coupling error model "
                f"(held-out {what} {pct(h['linear'][figure])} vs "
                f"{pct(h['svr'][figure])}): consider the method 'linear' or 'auto'")
    return None


def summary(verdict: dict[str, Any]) -> dict[str, Any]:
    """The verdict without its records: what the model file and ``fit --json`` keep."""
    return {k: v for k, v in verdict.items() if k not in ("records", "predictions", "centred", "trained")}
