"""Poses of a mass held out by pose, through the CLI: the model against the matrix.

Issue 32's check on an eight-gauge pose calibration (60 static poses of a known mass on
a robot arm, timestamped samples per pose):

1. the pose files joined as text with their header once (a directory's files in name
   order), or a joined file as given, or ``simulate --rig poses`` sets (fewer samples a pose);
2. ``fsdecouple init JOINED -o cfg.yaml`` once, on the whole file;
3. 5 folds by pose: fold k holds out poses k, k + 5, ... in file order; ``fit -c
   cfg.yaml`` (no ``--method``: the config's) on the other poses' lines, and ``apply``
   the model to the held-out poses' lines; each pose's figure is the median of its
   decoupled samples (a serial misread decouples to nonsense on any method);
4. the same folds for a 6 x M least-squares matrix with offset, f = C [u, 1], fitted on
   the training poses' median readings and scored on the held-out poses' medians;
5. per component the RMS error over all folds as a fraction of its largest applied
   load; the figure is the worst component's RMS of the model over the matrix's.

    python benchmarks/pose_heldout.py PATH_TO_POSE_DIRECTORY_OR_JOINED_CSV
    python benchmarks/pose_heldout.py --seeds 0 6 --samples 200

Exit 1 when a figure exceeds ``--limit`` (default 1.10, the issue's).
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from rig_heldout import run, run_here  # noqa: E402  (a process per command, or this one)

FOLDS = 5


def joined(source: Path, work: Path) -> Path:
    """A directory's CSV files joined as text under the first one's header (name order)."""
    if source.is_file():
        return source
    files = sorted(source.glob("*.csv"))
    lines = files[0].read_text().splitlines()[:1]
    for f in files:
        lines += [line for line in f.read_text().splitlines()[1:] if line.strip()]
    out = work / "joined.csv"
    out.write_text("\n".join(lines) + "\n")
    return out


def heldout(path: Path, work: Path, verdict: bool = True, run=run) -> tuple[np.ndarray, np.ndarray, str]:
    """Per component the RMS error [fraction of the largest load] of the model and of the
    matrix over the 5 pose folds, and the methods the folds' models decouple by; each
    command run by ``run`` (a process each, or :func:`rig_heldout.run_here`), each fold's
    fit with ``--no-verdict`` unless ``verdict``."""
    cfg = work / "cfg.yaml"
    guess = json.loads(run("init", str(path), "-o", str(cfg), "--force", "--json"))
    text = path.read_text().splitlines()
    header, body = text[0], [line for line in text[1:] if line.strip()]
    names = next(csv.reader([header]))
    loads = [names.index(guess["columns"][c]) for c in guess["components"]]
    outs = [names.index(guess["columns"][o]) for o in guess["outputs"]]
    cells = list(csv.reader(body))
    f = np.array([[float(r[i]) for i in loads] for r in cells])
    u = np.array([[float(r[i]) for i in outs] for r in cells])
    pose = np.concatenate([[0], np.cumsum((f[1:] != f[:-1]).any(axis=1))])
    n = pose.max() + 1
    applied = np.array([f[pose == p][0] for p in range(n)])
    reading = np.array([np.median(u[pose == p], axis=0) for p in range(n)])
    model = np.zeros_like(applied)
    matrix = np.zeros_like(applied)
    methods = []
    for k in range(FOLDS):
        test = np.arange(n) % FOLDS == k
        for name, keep in (("train.csv", ~test[pose]), ("test.csv", test[pose])):
            (work / name).write_text("\n".join([header, *np.asarray(body)[keep]]) + "\n")
        run("fit", str(work / "train.csv"), "-c", str(cfg), "-o", str(work / "m.json"), "--force",
            *([] if verdict else ["--no-verdict"]))
        methods.append(json.loads((work / "m.json").read_text()).get("method", "svr"))
        run("apply", str(work / "m.json"), str(work / "test.csv"), "-o", str(work / "out.csv"),
            "--force")
        with open(work / "out.csv", newline="") as fh:
            rows = list(csv.reader(fh))
        # apply appends the components (decoupled_fx where the log has a column fx), then
        # status
        end = rows[0].index("status")
        cols = list(range(end - len(guess["components"]), end))
        dec = np.array([[float(r[i]) for i in cols] for r in rows[1:]])
        held = np.flatnonzero(test)
        model[held] = [np.median(dec[pose[test[pose]] == p], axis=0) for p in held]
        design = np.column_stack([reading, np.ones(n)])
        c, *_ = np.linalg.lstsq(design[~test], applied[~test], rcond=None)
        matrix[test] = design[test] @ c
    scale = np.abs(applied).max(axis=0)
    rms = [np.sqrt(((e - applied) ** 2).mean(axis=0)) / scale for e in (model, matrix)]
    return rms[0], rms[1], ", ".join(sorted(set(methods)))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("source", nargs="?", type=Path,
                    help="a directory of pose files or a joined pose CSV (default: simulated)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0],
                    help="simulate --rig poses seeds, without a source")
    ap.add_argument("--samples", type=int, default=200, help="samples per simulated pose")
    ap.add_argument("--limit", type=float, default=1.10)
    ap.add_argument("--in-process", action="store_true",
                    help="run the commands in this process (the same CLI, without starting "
                         "Python for each)")
    ap.add_argument("--no-verdict", dest="verdict", action="store_false",
                    help="fit --no-verdict in each fold: the model alone (the config's method "
                         "auto, which needs the verdict, then fits svr)")
    args = ap.parse_args()
    worst = 0.0
    cases = [(str(args.source), args.source)] if args.source else \
        [(f"simulated seed {s}", s) for s in args.seeds]
    for label, case in cases:
        with tempfile.TemporaryDirectory() as tmp:
            work = Path(tmp)
            if isinstance(case, Path):
                path = joined(case, work)
            else:
                from fsdecouple.sim.poses import write_poses  # simulate --rig poses, fewer samples

                write_poses(work / "sim", seed=case, samples=args.samples)
                path = joined(work / "sim", work)
            m, c, methods = heldout(path, work, verdict=args.verdict,
                                    run=run_here if args.in_process else run)
        ratio = m.max() / c.max()
        worst = max(worst, ratio)
        print(f"{label}: worst component's held-out RMS error, model {100 * m.max():.1f} % "
              f"(decoupling by {methods}), matrix with offset {100 * c.max():.1f} % of the "
              f"largest load: ratio {ratio:.3f}")
    return 1 if worst > args.limit else 0


if __name__ == "__main__":
    raise SystemExit(main())
