"""In-situ recalibration with ``fit --prior`` on simulated eight-gauge pose sets (issue 32 item 7).

    python benchmarks/prior.py                 # seeds 0-4, 10 new poses, both drifts
    python benchmarks/prior.py --seeds 3 --poses 10 --drift 0.03 --kind gain

For each seed: the *old* model is ``init`` then ``fit`` on all 60 poses of the sensor
(:mod:`fsdecouple.sim.poses`); the sensor then drifts and is recalibrated in place on
``--poses`` random poses.  Two kinds of drift, the simulator's own: ``gain`` (every
gauge's gains by ``drift`` N(0, 1), its offsets by ``drift`` x span) and ``coupling``
(every entry of the gauge mix by ``drift`` x its RMS entry x N(0, 1), offsets kept).
Three models decode a fresh calibration of all 60 poses of the drifted sensor (pose
medians): the old model as it is, a fresh fit of the few new poses (``fit`` without
``--prior``: the library call the CLI makes, verdict off), and ``fit --prior`` the old
model (:func:`fsdecouple.fitting.prior.fit_with_prior`, the CLI's call).  Printed: each
one's worst component's RMS error [% F.S.], the ratios prior / fresh and prior / old
(below 1: the prior wins), what held-out error chose, and per kind the mean and the
largest ratio over the seeds.
"""

from __future__ import annotations

import argparse
import tempfile
import warnings
from pathlib import Path

import numpy as np

from fsdecouple.config import load_config
from fsdecouple.data.calibration import load_calibration
from fsdecouple.data.init_config import init_config
from fsdecouple.errors import InputError
from fsdecouple.evaluation.calibrate import fit
from fsdecouple.fitting.prior import fit_with_prior
from fsdecouple.sim.poses import PoseSet, pose_lines, simulate_poses

KINDS = ("gain", "coupling")


def worst(model, poses: PoseSet, fs: np.ndarray) -> float:
    """Worst component's RMS error [F.S.] of ``model`` on ``poses`` (their medians)."""
    u = np.array([np.median(x, axis=0) for x in poses.samples]) - model.zero
    f = model.decouple(u, rotate=False, exact=True)
    return float((np.sqrt(((f - poses.loads) ** 2).mean(axis=0)) / fs).max())


def one(seed: int, n_new: int, drift: float, kind: str, tmp: Path
        ) -> tuple[float, float, float, str]:
    """(old, fresh, prior) worst components [F.S.] and the prior's choice, for one seed."""
    old_set = simulate_poses(seed, 200)
    (tmp / "old.csv").write_text("\n".join(pose_lines(old_set)) + "\n")
    init_config(tmp / "old.csv", tmp / "cfg.yaml", force=True)
    settings = load_config(tmp / "cfg.yaml")
    old = fit(load_calibration(tmp / "old.csv", settings), settings, verdict=False)
    moved = {"drift": drift} if kind == "gain" else {"coupling": drift}
    new = simulate_poses(seed, 200, noise_seed=1, **moved)
    # the technician picks poses away from the rails (rails.py would leave the others out)
    top = 1023.0
    clear = np.flatnonzero(((new.truth > 0.06 * top) & (new.truth < 0.94 * top)).all(axis=1))
    pick = np.sort(np.random.default_rng(seed).choice(clear, n_new, replace=False))
    few = PoseSet(new.loads[pick], [new.samples[i] for i in pick], new.truth[pick], new.railing)
    (tmp / "new.csv").write_text("\n".join(pose_lines(few)) + "\n")
    calib = load_calibration(tmp / "new.csv", settings)
    test = simulate_poses(seed, 200, noise_seed=2, **moved)
    fs = np.asarray(settings.full_scale, dtype=float)
    try:
        fresh = worst(fit(calib, settings, verdict=False), test, fs)
    except InputError:
        fresh = float("inf")  # too few poses to fit at all
    model = fit_with_prior(calib, settings, old, "old.json",
                           lambda c: fit(c, settings, verdict=False))
    line = next(w for w in model.report.warnings if w.startswith("prior model"))
    chosen = line.split(": ", 1)[1].split(", chosen")[0]
    # the old model keeps its old zero: the drift of the offsets is part of its error
    return worst(old, test, fs), fresh, worst(model, test, fs), chosen


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--poses", type=int, default=10)
    parser.add_argument("--drift", type=float, default=0.03)
    parser.add_argument("--kind", choices=(*KINDS, "both"), default="both")
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    kinds = KINDS if args.kind == "both" else (args.kind,)
    with tempfile.TemporaryDirectory() as tmp:
        for kind in kinds:
            print(f"drift: {kind} {args.drift:g}, {args.poses} new poses")
            print(f"{'seed':>4} {'old %':>8} {'fresh %':>8} {'prior %':>8} {'prior/fresh':>11} "
                  f"{'prior/old':>9}  chosen")
            ratios = []
            for seed in range(args.seeds):
                o, f, p, chosen = one(seed, args.poses, args.drift, kind, Path(tmp))
                ratios.append((p / f, p / o))
                print(f"{seed:>4} {100 * o:8.3f} {100 * f:8.3f} {100 * p:8.3f} {p / f:11.3f} "
                      f"{p / o:9.3f}  {chosen}")
            r = np.array(ratios)
            print(f"mean {'':>26} {r[:, 0].mean():11.3f} {r[:, 1].mean():9.3f}")
            print(f"max  {'':>26} {r[:, 0].max():11.3f} {r[:, 1].max():9.3f}\n")


if __name__ == "__main__":
    main()
