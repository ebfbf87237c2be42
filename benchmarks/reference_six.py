"""Issue 14: fsdecouple's six-axis defaults against a straightforward reference.

    python benchmarks/reference_six.py               # seeds 0-7, per component
    python benchmarks/reference_six.py --seeds 0-1

:class:`Reference` is the paper's method written out plainly, sharing nothing with
fsdecouple's fitting (only libsvm): Sections 2-4 for N components,

1. zero-correct each (repetition, component) sweep by the mean of its zero-load rows
   (Section 3);
2. omega_a: least-squares slope through the origin of u_a on f_a over the a sweeps (eq. 2);
3. chi_ab: one libsvm eps-SVR per pair, trained on (u_b, u_a) of the b sweeps, where
   u_a = e_ab (Section 2.1, eq. 4), in the data's volts, with Table 2: ``-s 3 -t 2``,
   C = 1000, eps = 1e-4, tolerance 1e-3 and the Gaussian exp(-|x - y|^2 / 2 delta^2)
   of Section 2.2 with delta^2 = 1, i.e. libsvm's gamma = 1 / (2 delta^2) = 0.5;
4. eq. (11): f_a = [u_a - sum_b chi_ab(u_b)] / k_a.

For each simulated sensor (fsdecouple.sim.six_axis, as ``simulate --components 6``)
it prints every component's combined-load RMS error over the floor (the true
coupling, eq. (1) solved exactly) and over the least-squares matrix's, for the
reference, fsdecouple's defaults (``zero: fit``) and fsdecouple with ``zero: rows``
(which is the reference's zeroing: the two should agree to the table path's 1e-9).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from libsvm import svmutil

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import fsdecouple.sim.six_axis as six  # noqa: E402

TABLE2 = "-s 3 -t 2 -g 0.5 -c 1000 -p 0.0001 -e 0.001 -q"  # gamma = 1 / (2 delta^2), delta^2 = 1


class Reference:
    """The paper's decoupler fitted from a raw long table (``repetition, axis``, loads, outputs)."""

    def __init__(self, table, loads=six.COMPONENTS, outputs=six.OUTPUTS, options=TABLE2):
        f = table[list(loads)].to_numpy(float)
        u = table[list(outputs)].to_numpy(float)
        sweep = table["axis"].map({c: i for i, c in enumerate(loads)}).to_numpy()
        for _, idx in table.groupby(["repetition", "axis"]).indices.items():
            u[idx] -= u[idx[(f[idx] == 0).all(axis=1)]].mean(axis=0)  # Section 3
        self.n = n = len(loads)
        self.k = np.array([f[sweep == a, a] @ u[sweep == a, a] / (f[sweep == a, a] @ f[sweep == a, a])
                           for a in range(n)])  # eq. (2)
        # lists: libsvm's input whether or not it found scipy (fsdecouple loads it without)
        self.svr = {(a, b): svmutil.svm_train(u[sweep == b, a].tolist(),
                                              u[sweep == b, b].reshape(-1, 1).tolist(), options)
                    for b in range(n) for a in range(n) if a != b}  # eq. (4)
        self.matrix = np.linalg.lstsq(u, f, rcond=None)[0]  # the calibration matrix, F = U M

    def chi(self, a: int, b: int, x: np.ndarray) -> np.ndarray:
        x = np.ascontiguousarray(x, dtype=float).reshape(-1, 1)
        return np.asarray(svmutil.svm_predict([0.0] * len(x), x.tolist(), self.svr[a, b], "-q")[0])

    def decouple(self, u: np.ndarray) -> np.ndarray:
        e = np.zeros_like(u)
        for a, b in self.svr:
            e[:, a] += self.chi(a, b, u[:, b])
        return (u - e) / self.k  # eq. (11)


def sensor_case(seed: int):
    """(sensor, raw calibration table, tared task outputs, true loads) of one seed."""
    sensor = six.six_axis_sensor(seed)
    table = six.simulate_calibration(sensor, seed=seed)
    volts, loads = six.simulate_task(sensor, seed=seed)
    u = volts[list(six.OUTPUTS)].to_numpy()
    return sensor, table, u - u[:six.TARE_ROWS].mean(axis=0), loads[list(six.COMPONENTS)].to_numpy()


def rms(f: np.ndarray, truth: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean((f - truth) ** 2, axis=0))


def main() -> int:
    from fsdecouple import load_config
    from fsdecouple.data.calibration import from_table
    from fsdecouple.fitting.fit import fit

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-7", help="a range, e.g. 0-7")
    args = ap.parse_args()
    lo, _, hi = args.seeds.partition("-")
    settings = load_config(ROOT / "configs" / "six-axis.yaml")
    np.set_printoptions(precision=2, linewidth=150)
    worst: dict[str, list[tuple[float, float]]] = {}
    t0 = time.perf_counter()
    for seed in range(int(lo), int(hi or lo) + 1):
        sensor, table, u, f = sensor_case(seed)
        floor = rms(sensor.solve(u), f)
        ref = Reference(table)
        linear = rms(u @ ref.matrix, f)
        rows = {"reference": rms(ref.decouple(u), f)}
        for name, zero in (("fsdecouple default", None), ("fsdecouple zero: rows", "rows")):
            s = replace(settings, zero=zero) if zero else settings
            rows[name] = rms(fit(from_table(table, s), s, workers=1).decouple(u, rotate=False), f)
        print(f"seed {seed}: linear matrix / floor {linear / floor}")
        for name, r in rows.items():
            print(f"  {name:22s} / floor {r / floor} / linear {r / linear}")
            worst.setdefault(name, []).append((float(np.max(r / floor)), float(np.max(r / linear))))
    print("\n| method | worst component / floor, mean (max) | worst component / linear, mean (max) |")
    print("|---|---|---|")
    for name, v in worst.items():
        a = np.array(v)
        print(f"| {name} | {a[:, 0].mean():.2f}× ({a[:, 0].max():.2f}×) | "
              f"{a[:, 1].mean():.2f}× ({a[:, 1].max():.2f}×) |")
    print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
