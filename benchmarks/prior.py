"""In-situ recalibration with ``fit --prior`` on simulated eight-gauge pose sets (issue 32 item 7).

    python benchmarks/prior.py                 # seeds 0-4, 10 new poses
    python benchmarks/prior.py --seeds 3 --poses 10 --drift 0.03

For each seed: the *old* model is ``init`` then ``fit`` on all 60 poses of the sensor
(:mod:`fsdecouple.sim.poses`); the sensor then drifts (every gauge's gains by ``drift``
N(0, 1), its offsets by ``drift`` x span) and is recalibrated in place on ``--poses``
random poses.  Three models decode a fresh calibration of all 60 poses of the drifted
sensor (pose medians): the old model as it is, a fresh fit of the few new poses, and the
fit of the new poses ``--prior`` the old model (lambda by held-out error,
:mod:`fsdecouple.fitting.prior`).  Printed: each one's worst component's RMS error
[% F.S.] and the ratios prior / fresh and prior / old (below 1: the prior wins).
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
from fsdecouple.fitting.fit import fit
from fsdecouple.fitting.prior import prior_set
from fsdecouple.sim.poses import PoseSet, pose_lines, simulate_poses


def worst(model, poses: PoseSet, fs: np.ndarray) -> float:
    """Worst component's RMS error [F.S.] of ``model`` on ``poses`` (their medians)."""
    u = np.array([np.median(x, axis=0) for x in poses.samples]) - model.zero
    f = model.decouple(u, rotate=False, exact=True)
    return float((np.sqrt(((f - poses.loads) ** 2).mean(axis=0)) / fs).max())


def one(seed: int, n_new: int, drift: float, tmp: Path) -> tuple[float, float, float]:
    old_set = simulate_poses(seed, 200)
    (tmp / "old.csv").write_text("\n".join(pose_lines(old_set)) + "\n")
    init_config(tmp / "old.csv", tmp / "cfg.yaml", force=True)
    settings = load_config(tmp / "cfg.yaml")
    old = fit(load_calibration(tmp / "old.csv", settings), settings, tables=False)
    new = simulate_poses(seed, 200, drift=drift, noise_seed=1)
    # the technician picks poses away from the rails (rails.py would leave the others out)
    top = 1023.0
    clear = np.flatnonzero(((new.truth > 0.06 * top) & (new.truth < 0.94 * top)).all(axis=1))
    pick = np.sort(np.random.default_rng(seed).choice(clear, n_new, replace=False))
    few = PoseSet(new.loads[pick], [new.samples[i] for i in pick], new.truth[pick], new.railing)
    (tmp / "new.csv").write_text("\n".join(pose_lines(few)) + "\n")
    calib = load_calibration(tmp / "new.csv", settings)
    test = simulate_poses(seed, 200, drift=drift, noise_seed=2)
    fs = np.asarray(settings.full_scale, dtype=float)
    try:
        fresh = worst(fit(calib, settings, tables=False), test, fs)
    except InputError:
        fresh = float("inf")  # too few poses to fit at all
    prior = worst(fit(prior_set(calib, settings, old, "old.json"), settings, tables=False), test, fs)
    # the old model keeps its old zero: the drift of the offsets is part of its error
    return worst(old, test, fs), fresh, prior


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--poses", type=int, default=10)
    parser.add_argument("--drift", type=float, default=0.03)
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    print(f"{'seed':>4} {'old %':>8} {'fresh %':>8} {'prior %':>8} {'prior/fresh':>11} {'prior/old':>9}")
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            o, f, p = one(seed, args.poses, args.drift, Path(tmp))
            print(f"{seed:>4} {100 * o:8.3f} {100 * f:8.3f} {100 * p:8.3f} {p / f:11.3f} {p / o:9.3f}")


if __name__ == "__main__":
    main()
