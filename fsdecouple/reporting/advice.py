"""What ``fit`` advises: the refinement K from eq. (6), and whether to ``--tune``."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

# The recommended K (recommend_refine): the largest eq. (6) estimate E2 [fraction
# of F.S.] is brought below REFINE_TARGET, about the noise floor of a calibration
# (0.5 mV on ~1.3 V full-scale outputs for the simulated sensor = 0.04 %).
REFINE_TARGET = 5e-4


def recommend_refine(second_order: float, slope: float, n: int = 3) -> int | None:
    """The K to recommend for a model, from its eq. (6) estimate and its slopes.

    ``second_order``: the largest eq. (6) estimate E2 = max|chi_ab'| * coupling
    fraction of input b [fraction of F.S.]; ``slope``: the largest max|chi'|.
    0 when E2 is already at most REFINE_TARGET; None when (N - 1) max|chi'| >= 1,
    where the iteration is not known to contract.  Otherwise the smallest K >= 1
    with E2 * max|chi'|^K <= REFINE_TARGET.  The factor per step is taken as
    max|chi'|, not the contraction bound (N - 1) max|chi'|: on simulated sensors
    (benchmarks/refine.py --sweep, coupling 1x to 8x the sample's, max|chi'|
    0.05 to 0.44) the combined-load error fell at about that rate: the K needed
    to bring it within the 0.04 % F.S. noise of the fit's own error floor was
    1, 1, 2, 3, 4, 4, and this rule gives 1, 2, 2, 3, 5, 7 (never too few; a
    step costs about one table evaluation), where the bound's factor asks 1 to 41.
    """
    if not np.isfinite(second_order) or second_order <= REFINE_TARGET:
        return 0
    if not (np.isfinite(slope) and (n - 1) * slope < 1.0):
        return None
    if slope <= 0.0:
        return 1
    return max(1, int(np.ceil(np.log(REFINE_TARGET / second_order) / np.log(slope))))


def refine_advice(checks: Iterable, n: int) -> dict:
    """The eq. (6) figure ``fit`` prints, from the Section 2.1 checks (checks.py).

    ``second_order``: the largest eq. (6) estimate [fraction of F.S.] and its
    ``chi``; ``slope``: the largest max|chi'|; ``recommended``: K by
    :func:`recommend_refine` (0: eq. (11) is within the noise; None: no K is
    known to converge).
    """
    checks = list(checks)
    worst = max((c for c in checks if c.name == "second_order"), key=lambda c: c.value)
    slope = max(c.value for c in checks if c.name == "slope")
    return {"second_order": worst.value, "chi": worst.subject, "slope": slope,
            "target": REFINE_TARGET, "recommended": recommend_refine(worst.value, slope, n)}


def tune_advice(advice: dict, tune: dict | None, *, can_tune: bool = True,
                linear: bool = False) -> dict:
    """Whether ``fit`` recommends ``--tune`` with refinement, and on what evidence.

    On the simulated sensors of benchmarks/accuracy.py, ``--tune --refine 3`` was
    the most accurate option at every coupling level from the sample's (1.1-2.7 %)
    up, with hysteresis too; below that, where eq. (11) as written is within the
    noise (``advice["recommended"] == 0``), neither is asked for.  ``tune``: the
    model's ``report.tune`` record, None for an untuned fit.

    ``recommended``: ``--tune`` is advised (untuned fits whose K >= 1; tuned fits
    whose held-out figures chose a grid setting over Table 2); ``basis``:
    ``coupling`` (eq. 6 only: run ``--tune`` to see its held-out figures),
    ``heldout``, ``untunable`` (``can_tune`` False: the set has no held-out protocol
    for tuning, only refinement can be advised) or ``linear`` (a linear model: neither
    applies); ``gain``: 1 - chosen / Table 2's held-out figure (tuned fits).
    """
    k = advice["recommended"]
    if linear:
        return {"recommended": False, "basis": "linear", "gain": None}
    if tune is None:
        if not can_tune:
            return {"recommended": False, "basis": "untunable", "gain": None}
        return {"recommended": bool(k), "basis": "coupling", "gain": None}
    cands = tune["candidates"]
    t2, pick = cands[0]["figure"], cands[tune["chosen"]]["figure"]
    gain = 1.0 - pick / t2 if t2 and pick is not None else None
    return {"recommended": k is not None and tune["chosen"] != 0, "basis": "heldout",
            "gain": gain}
