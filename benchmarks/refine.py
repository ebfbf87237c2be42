"""Cost of second-order refinement through the tables, and the sweep behind fit's K.

    python benchmarks/refine.py            # K = 3 vs K = 0: 1 M vectors in memory, 10 M-row apply
    python benchmarks/refine.py --sweep    # recommended K vs measured, simulated sensors
    python benchmarks/refine.py --docs     # the cost run, written into docs/benchmarks.md's block

The ratio is of medians measured in the same run (other jobs on a shared machine
slow both alike).  K steps and the forces are K + 1 evaluations of every chi, each
the work of unrefined decoupling, so the in-memory ratio cannot fall below about
K + 1 less the shared per-call work (issue 24 accepts that).  The second line is
the same comparison for ``fsdecouple apply`` of a 10 M-row CSV log (reading and
writing included; ``--apply-rows``), each in a child process, K = 0 and K run in
turn: the goal is ``apply --refine 3`` at most APPLY_GOAL x ``apply``.  The sweep
prints, per coupling factor, the eq. (6) estimate, fit's recommended K and the
combined-load error [% F.S.] for K = 0 .. 6 over 20 000 noise-free combined loads
(rows that did not settle counted apart).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from run import machine, median_child, write_log  # noqa: E402

from fsdecouple import load_config
from fsdecouple.core.modelfile import save_model
from fsdecouple.data.calibration import from_table
from fsdecouple.evaluation.checks import assumption_checks
from fsdecouple.fitting.fit import fit
from fsdecouple.reporting.advice import refine_advice
from fsdecouple.sim.simulate import SimulatedSensor, simulate_calibration


def sensor_model(factor: float, settings):
    base = SimulatedSensor()
    sensor = replace(base, amplitude=tuple(tuple(factor * v for v in r) for r in base.amplitude))
    return sensor, fit(from_table(simulate_calibration(sensor, seed=3), settings), settings)


APPLY_GOAL = 1.2  # issue 24: apply --refine 3 / apply on a 10 M-row log


def cost(rows: int, repeats: int, k: int, apply_rows: int = 10_000_000,
         apply_repeats: int = 3) -> str:
    """Both comparisons, printed and returned as the docs' lines; ``apply_repeats`` runs of
    each apply (the median's)."""
    started = machine()
    _, model = sensor_model(1.0, load_config())
    r = model.calibrated_range
    u = np.random.default_rng(0).uniform(r[:, 0], r[:, 1], (rows, 3))
    times = {0: [], k: []}
    # both on numpy: a K = 3 call of a million rows is enough work for the compiled
    # kernel and K = 0 is not (core/table_path.py COMPILED_WORK), which is not the
    # refinement's cost
    model.decouple(u[:100_000], refine=k, compiled=False)  # warm the threads and work arrays
    for _ in range(repeats):
        for kk in times:  # interleaved, so drift hits both
            t0 = time.perf_counter()
            model.decouple(u, refine=kk, compiled=False)
            times[kk].append(time.perf_counter() - t0)
    base, refined = (statistics.median(times[kk]) for kk in (0, k))
    memory = (f"in memory, {rows:,} vectors through the tables, median of {repeats}: K = 0 "
              f"{base:.4f} s, K = {k} {refined:.4f} s, ratio **{refined / base:.2f}**")
    print(memory)
    with tempfile.TemporaryDirectory(prefix="fsdecouple-bench-refine-") as tmp:
        tmp = Path(tmp)
        mfile, log = tmp / "model.json", tmp / "log.csv"
        save_model(model, mfile)
        write_log(log, apply_rows, model)
        args = [sys.executable, "-m", "fsdecouple", "apply", mfile, log, "-o", tmp / "f.csv", "--force"]
        runs: dict[int, list[float]] = {0: [], k: []}
        for _ in range(apply_repeats):  # in turn, so drift hits both
            for kk in runs:
                runs[kk].append(median_child([*args, "--refine", str(kk)], 1)[0])
        walls = {kk: statistics.median(v) for kk, v in runs.items()}
    ratio = walls[k] / walls[0]
    applied = (f"`fsdecouple apply`, {apply_rows:,}-row CSV, median of {apply_repeats}: "
               f"K = 0 {walls[0]:.2f} s, K = {k} {walls[k]:.2f} s, ratio **{ratio:.2f}** "
               f"(goal ≤ {APPLY_GOAL}: {'PASS' if ratio <= APPLY_GOAL else 'FAIL'})")
    print(applied)
    return f"Measured by `benchmarks/refine.py`: {started}.\n\n* {memory}\n* {applied}"


def sweep() -> None:
    settings = load_config()
    for factor in (1, 2, 3, 4, 6, 8):
        sensor, model = sensor_model(factor, settings)
        advice = refine_advice(assumption_checks(model), 3)
        span = np.array(sensor.load_span) * np.asarray(sensor.full_scale)[:, None]
        f = np.random.default_rng(1).uniform(span[:, 0], span[:, 1], (20_000, 3))
        u = sensor.voltages(f)
        cells = []
        for k in range(7):
            settled = np.empty(len(u), dtype=bool)
            err = np.abs(model.decouple(u, refine=k, converged=settled) - f) / sensor.full_scale
            more = f" ({(~settled).sum()} not settled)" if not settled.all() else ""
            cells.append(f"{100 * np.nanmax(err):.4f}{more}")
        print(f"coupling x{factor}: max|chi'| {advice['slope']:.3f}, eq. (6) "
              f"{100 * advice['second_order']:.3f} %, recommended K {advice['recommended']}; "
              "max error % F.S. of the settled rows by K = 0..6: " + ", ".join(cells))


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sweep", action="store_true")
    ap.add_argument("--rows", type=int, default=1_000_000)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--apply-rows", type=int, default=10_000_000,
                    help="rows of the apply comparison's log (issue 24's goal is on 10 M)")
    ap.add_argument("--apply-repeats", type=int, default=3,
                    help="runs of each apply, K = 0 and K in turn (the median's)")
    ap.add_argument("-k", type=int, default=3)
    ap.add_argument("--docs", "--readme", dest="docs", action="store_true",
                    help="also rewrite docs/benchmarks.md's refine-benchmarks block (the default cost run)")
    args = ap.parse_args()
    if args.sweep:
        sweep()
    else:
        text = cost(args.rows, args.repeats, args.k, args.apply_rows, args.apply_repeats)
        if args.docs:
            from readme_blocks import replace_block, written

            print(written(replace_block("refine-benchmarks", text), "refine-benchmarks"))
