"""Held-out protocols: which calibration points a validation round trains on and tests on.

* ``repetitions`` (three or more repetitions): Section 4.1's protocol.  Each round
  holds out whole repetitions (two by default, "test data I" and "test data II")
  and trains on the others.
* ``levels`` (for fewer than three repetitions, e.g. a lab's single repetition):
  round k holds out the k-th loaded point of every sweep, in file order, and
  trains on the rest; zero-load rows always stay in training.  A held-out point
  whose load lies beyond the loads left in its sweep (the largest, or the most
  negative) can only be extrapolated, so it is scored apart as an *end* point.
* ``poses`` (poses of a known mass, issue 32: no unloaded row, so no sweep to take
  levels from): round k of :data:`POSE_FOLDS` holds out points k, k + 5, k + 10, ...
  in file order (every fifth pose) and trains on the rest.

All serve ``cv`` and the verdict of ``fit``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..data.calibration import CalibrationSet
from ..errors import InputError

PROTOCOLS = ("repetitions", "levels", "poses")
POSE_FOLDS = 5  # issue 32: "held out by pose (5 folds)"
ROUNDS = 3  # Section 4.1: "the cross validation is repeated three times"
HELD_OUT = 2  # "test data I" and "test data II"
MIN_REPETITIONS = HELD_OUT + 1  # two held out, at least one to train


@dataclass(frozen=True)
class HeldOutRound:
    """One round: a training set and the held-out sets scored against it.

    ``tests`` are (label, points): the held-out repetition's number, or the level k.
    ``end`` holds the levels protocol's end points (extrapolation), scored apart.
    """

    index: int
    train: CalibrationSet
    tests: tuple[tuple[int, CalibrationSet], ...]
    end: CalibrationSet | None = None


def is_pose_set(calib: CalibrationSet) -> bool:
    """Averaged poses (data/poses.py) with no unloaded row (``zero: intercept``): a robot
    arm's poses of a mass, whose sweeps (and so load levels) are no more than file order."""
    return getattr(calib, "zero", None) == "intercept" and getattr(calib, "noise", None) is not None


def choose_protocol(calib: CalibrationSet, protocol: str | None = None) -> str:
    """``repetitions`` with three or more repetitions, else ``poses`` for a pose set
    (:func:`is_pose_set`), else ``levels``; or check the given one."""
    if protocol is None:
        if len(calib.repetitions) >= MIN_REPETITIONS:
            return "repetitions"
        return "poses" if is_pose_set(calib) else "levels"
    if protocol not in PROTOCOLS:
        raise InputError(f"protocol {protocol!r}: expected one of {', '.join(PROTOCOLS)}",
                         argument="protocol")
    if protocol == "repetitions" and len(calib.repetitions) < MIN_REPETITIONS:
        raise InputError(
            f"{calib.source}: the repetitions protocol needs at least {MIN_REPETITIONS} "
            f"repetitions (two held out, one to train); the set has {len(calib.repetitions)}: "
            "use the protocol", remedy=("protocol", "levels")
        )
    return protocol


def repetition_rounds(calib: CalibrationSet, folds: list[list[int]]) -> list[HeldOutRound]:
    """One round per fold: train on the other repetitions, test on each held-out one."""
    reps = calib.repetitions
    return [
        HeldOutRound(r, calib.subset([rep for rep in reps if rep not in fold]),
                     tuple((rep, calib.subset([rep])) for rep in fold))
        for r, fold in enumerate(folds, start=1)
    ]


def level_index(calib: CalibrationSet) -> tuple[np.ndarray, np.ndarray]:
    """(k, prime load) per point: k is the point's rank among its sweep's loaded points.

    Ranks count from 1 in file order; zero-load rows get 0.
    """
    pts = calib.points
    forces = calib.forces
    axis = pts["axis"].map({a: i for i, a in enumerate(calib.layout.labels)}).to_numpy()
    prime = forces[np.arange(len(pts)), axis]
    loaded = (forces != 0.0).any(axis=1)
    k = np.zeros(len(pts), dtype=int)
    for _, idx in pts.groupby(["repetition", "axis"], sort=False).indices.items():
        sweep = idx[loaded[idx]]
        k[sweep] = np.arange(1, sweep.size + 1)
    return k, prime


def level_rounds(calib: CalibrationSet) -> list[HeldOutRound]:
    """Round k holds out the k-th loaded point of every sweep (zero rows always train)."""
    k, prime = level_index(calib)
    pts = calib.points
    sweeps = pts.groupby(["repetition", "axis"], sort=False).indices
    for (rep, axis), idx in sweeps.items():
        if (k[idx] > 0).sum() < 2:
            first = pts.iloc[idx[0]]
            raise InputError(
                f"{first['file']}: the {axis} sweep of repetition {rep} has "
                f"{(k[idx] > 0).sum()} loaded point; holding out load levels needs at least 2 "
                "per sweep (one to test, one to train)"
            )
    rounds = []
    for level in range(1, int(k.max()) + 1):
        held = k == level
        end = np.zeros(len(pts), dtype=bool)
        for idx in sweeps.values():
            out, keep = idx[held[idx]], idx[~held[idx]]
            for i in out:  # beyond every load left in the sweep: extrapolation
                end[i] = prime[i] > prime[keep].max() or prime[i] < prime[keep].min()
        interior = held & ~end
        rounds.append(HeldOutRound(
            level, calib.select(~held),
            ((level, calib.select(interior)),) if interior.any() else (),
            calib.select(end) if end.any() else None,
        ))
    return rounds


def pose_rounds(calib: CalibrationSet, folds: int = POSE_FOLDS) -> list[HeldOutRound]:
    """Round k (1 .. ``folds``) holds out points k - 1, k - 1 + folds, ... in file order."""
    n = len(calib.points)
    if n < 2 * folds:
        raise InputError(f"{calib.source}: {n} poses; holding out poses in {folds} folds needs "
                         f"at least {2 * folds} (each round trains on the other folds)")
    index = np.arange(n)
    return [HeldOutRound(k + 1, calib.select(index % folds != k),
                         ((k + 1, calib.select(index % folds == k)),))
            for k in range(folds)]


# --- folds ------------------------------------------------------------------------


def parse_folds(text: str) -> list[list[int]]:
    """``"1,2;3,4;5,6"`` -> ``[[1, 2], [3, 4], [5, 6]]``: the held-out repetitions per round."""
    folds = []
    for part in text.split(";"):
        try:
            fold = [int(v) for v in part.split(",")]
        except ValueError:
            raise InputError(
                f"folds {text!r}: expected repetition numbers, ',' within a round and "
                "';' between rounds, e.g. '1,2;3,4;5,6'", argument="folds"
            ) from None
        folds.append(fold)
    if len(folds) > MAX_ROUNDS:
        raise InputError(f"folds: {len(folds)} rounds; at most {MAX_ROUNDS} (each round fits "
                         "every method once)", argument="folds")
    return folds


MAX_ROUNDS = 100


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
            raise InputError(f"folds: round {r} holds out no repetition", argument="folds")
        for rep in fold:
            if rep not in repetitions:
                raise InputError(
                    f"folds: round {r} holds out repetition {rep}, which the calibration "
                    f"set does not have (it has {have})", argument="folds"
                )
        if len(set(fold)) != len(fold):
            raise InputError(f"folds: round {r} names a repetition twice", argument="folds")
        if len(set(fold)) >= len(repetitions):
            raise InputError(f"folds: round {r} holds out every repetition; none is left to train",
                             argument="folds")


def rounds_for(calib: CalibrationSet, protocol: str, folds: list[list[int]] | None = None
               ) -> list[HeldOutRound]:
    """The rounds of a protocol: ``folds`` (default :func:`default_folds`) for repetitions."""
    if protocol == "levels":
        return level_rounds(calib)
    if protocol == "poses":
        return pose_rounds(calib)
    folds = folds if folds is not None else default_folds(calib.repetitions)
    check_folds(folds, calib.repetitions)
    return repetition_rounds(calib, folds)
