"""`cv` with a config that states Table 2 is the paper's algorithm (issue 34, settings obeyed).

An independent reference of Sections 2-4, written here from the paper and libsvm alone:
the sample's CSV files read with the csv module, each sweep zeroed by its own zero-load
row (Section 3), omega by least squares through the origin (eq. 2), each chi a libsvm
epsilon-SVR with Table 2's options exactly as written (``-s 3 -t 2 -g 0.5 -c 1000 -p 1e-4
-e 1e-3``, points fed in file order), libsvm's own prediction in eq. (11), and gamma
(eq. 12) on each held-out repetition.  `cv` (three rounds holding out 1,2; 3,4; 5,6) must
agree with it on every svr gamma.  Before the fix fit replaced the written 0.001 with
0.000912 (its noise rule) and agreed only by chance of the solver's path.
"""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from conftest import ROOT, SAMPLE, invoke

AXES = "xyz"
FULL_SCALE = {"x": 100.0, "y": 100.0, "z": 150.0}  # Section 3
TABLE2 = "-s 3 -t 2 -g 0.5 -c 1000 -p 0.0001 -e 0.001 -q"
# [F.S.] cv decouples by its chi tables, within decouple.MAX_SURROGATE_ERROR (2.5e-7 F.S.
# of output) of the kernel sums, and extrapolates by the tangent a held-out output that
# passes its training range by noise (0.5 mV, ~4e-4 F.S.), where libsvm extrapolates by
# the kernel: the two differ by the slope change over that step, well below 1e-5 F.S.
AGREE = 1e-5


def _sweeps(rep: int) -> dict[str, np.ndarray]:
    """Rows of rep<rep>.csv per sweep axis, (f, u) zeroed by the sweep's zero-load row."""
    with open(SAMPLE / "calibration" / f"rep{rep}.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    out = {}
    for a in AXES:
        mine = [r for r in rows if r["axis"] == a]
        f = np.array([[float(r[f"f{b}"]) for b in AXES] for r in mine])
        u = np.array([[float(r[f"u{b}"]) for b in AXES] for r in mine])
        zero = u[(f == 0.0).all(axis=1)].mean(axis=0)  # one zero row per sweep here
        out[a] = (f, u - zero)
    return out


def _reference_gammas(train: list[int], tests: list[int]) -> dict[tuple[int, str], float]:
    from libsvm import svmutil

    data = {r: _sweeps(r) for r in train + tests}
    k = {}
    for i, a in enumerate(AXES):  # eq. (2)
        f = np.concatenate([data[r][a][0][:, i] for r in train])
        u = np.concatenate([data[r][a][1][:, i] for r in train])
        k[a] = float(f @ u / (f @ f))
    chi = {}
    for j, b in enumerate(AXES):  # chi_ab from the b sweeps: u_a as a function of u_b
        x = np.concatenate([data[r][b][1][:, j] for r in train])
        for i, a in enumerate(AXES):
            if a != b:
                y = np.concatenate([data[r][b][1][:, i] for r in train])
                chi[(a, b)] = svmutil.svm_train(y.tolist(), [[v] for v in x], TABLE2)

    def predict(m, x):
        out, _, _ = svmutil.svm_predict([0.0] * len(x), [[v] for v in x], m, "-q")
        return np.array(out)

    gammas = {}
    for r in tests:
        for i, a in enumerate(AXES):
            f_true, u = data[r][a]
            forces = np.empty_like(u)
            for p, c in enumerate(AXES):  # eq. (11)
                u_prime = u[:, p] - sum(predict(chi[(c, b)], u[:, q])
                                        for q, b in enumerate(AXES) if b != c)
                forces[:, p] = u_prime / k[c]
            err = np.abs(forces - f_true)
            gammas[(r, a)] = sum(err[:, q].max() for q in range(3) if q != i) / FULL_SCALE[a]
    return gammas  # eq. (12)


@pytest.mark.slow  # cv's three rounds of every baseline
def test_cv_with_the_papers_config_is_the_papers_algorithm(tmp_path):
    out = tmp_path / "cv.json"
    invoke(["cv", SAMPLE / "calibration", "-c", ROOT / "configs" / "paper-sensor.yaml",
            "-o", out, "--workers", "1"])
    records = [r for r in json.loads(out.read_text())["records"]
               if r["method"] == "svr" and r["metric"] == "gamma"]
    folds = {1: [1, 2], 2: [3, 4], 3: [5, 6]}
    assert {r["round"] for r in records} == set(folds)
    for rnd, held in folds.items():
        train = [r for r in range(1, 7) if r not in held]
        ref = _reference_gammas(train, held)
        for rec in (r for r in records if r["round"] == rnd):
            want = ref[(int(rec["test_set"]), rec["axis"])]
            assert rec["value"] == pytest.approx(want, abs=AGREE), (rnd, rec, want)


def test_the_papers_config_writes_the_papers_eq_11():
    """configs/paper-sensor.yaml says that with it fsdecouple runs the paper's algorithm;
    it left extrapolation to the default, tangent, so a chi beyond its calibrated inputs
    was not eq. (10)'s kernel sum (0.26 N apart on a log 1.3 times the sample's loads)."""
    from conftest import ROOT

    from fsdecouple.config import load_config

    s = load_config(ROOT / "configs" / "paper-sensor.yaml")
    assert (s.extrapolation, s.refine, s.zero) == ("kernel", 0, "rows")
    assert (s.svr.C, s.svr.epsilon, s.svr.gamma, s.svr.tolerance) == (1000, 1e-4, 0.5, 1e-3)
