"""Held-out load levels on a lever-arm rig, through the CLI: the model against the matrix.

The protocol of issue 22's check, on ``simulate --rig lever-arm`` files:

1. ``fsdecouple init FILE -o cfg.yaml`` once, on the whole file;
2. for each load level k (the k-th loaded row of every sweep): write the file without
   those rows, ``fit --method auto -c cfg.yaml`` on it, zero-correct the held-out rows
   by the zero row before them, write their outputs as a log with the file's own output
   columns (``Fx .. Mz``) and ``apply`` the model to it;
3. the same folds for the least-squares calibration matrix f = C u (Section 1);
4. per component, the RMS error over all folds as a fraction of its full scale; the
   figure is the worst component's RMS of the model divided by the matrix's.

The same folds also fit a least-squares fit with squared terms, f = C [u, u^2] (the
reference issue 22 quotes: 0.62 x the matrix on the public rig file), to show how
nonlinear a file is.  ``--rig quadratic`` is the stand-in for that file.

    python benchmarks/rig_heldout.py --seeds 0 1 2
    python benchmarks/rig_heldout.py --rig quadratic --seeds 0 1 2 --limit 0.85
    python benchmarks/rig_heldout.py --gauges 8 --seeds 0 1 2    # M > N: eight gauges
    python benchmarks/rig_heldout.py --seeds 0 --method svr --no-verdict   # the model alone
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import io
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

CLI = [sys.executable, "-m", "fsdecouple"]


def run(*args: str) -> str:
    done = subprocess.run([*CLI, *args], capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"fsdecouple {' '.join(args)}: exit {done.returncode}\n{done.stderr}")
    return done.stdout


def run_here(*args: str) -> str:
    """:func:`run` without a process per command: the same CLI (its parsing, checks and
    rendering) called in this process, its output captured (``--in-process``)."""
    from fsdecouple.cli import app

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = app(args=list(args), prog_name="fsdecouple", standalone_mode=False)
    if code:
        raise SystemExit(f"fsdecouple {' '.join(args)}: exit {code}\n{err.getvalue()}")
    return out.getvalue()


def read(path: Path) -> tuple[list[str], list[list[str]]]:
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], [r for r in rows[1:] if any(c.strip() for c in r)]


def heldout(path: Path, work: Path, method: str = "auto", verdict: bool = True,
            run=run) -> dict:
    """Both methods' per-component RMS errors [fraction of F.S.] over the level folds;
    each fold fitted by ``fit --method method`` (``--no-verdict`` unless ``verdict``), each
    command run by ``run`` (a process each, or :func:`run_here`)."""
    cfg = work / "cfg.yaml"
    guess = json.loads(run("init", str(path), "-o", str(cfg), "--force", "--json"))
    header, rows = read(path)
    comps = guess["components"]
    load_cols = [header.index(guess["columns"][c]) for c in comps]
    out_cols = [header.index(guess["columns"][o]) for o in guess["outputs"]]
    fs = np.array([guess["full_scale"][c] for c in comps])
    f = np.array([[float(r[i]) for i in load_cols] for r in rows])
    u = np.array([[float(r[i]) for i in out_cols] for r in rows])
    zero = ~f.any(axis=1)
    level = np.zeros(len(rows), dtype=int)  # the k-th loaded row after a zero row
    base = np.zeros(len(rows), dtype=int)  # the zero row before each row
    k = last = 0
    for i in range(len(rows)):
        if zero[i]:
            k, last = 0, i
        else:
            k += 1
            level[i] = k
        base[i] = last
    uc = u - u[base]  # zero-corrected by the zero row before
    span = np.abs(uc).max(axis=0)

    def squares(v):
        return np.column_stack([v, (v / span) ** 2])

    chosen = []  # what fit kept in each fold (auto: svr, the model, or linear)
    err = {"model": [], "matrix": [], "squares": []}
    for lv in range(1, level.max() + 1):
        held = level == lv
        train = work / f"train{lv}.csv"
        with open(train, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(header)
            w.writerows(r for r, h in zip(rows, held, strict=True) if not h)
        model = work / f"model{lv}.json"
        run("fit", str(train), "-c", str(cfg), "-o", str(model), "--method", method, "--force",
            *([] if verdict else ["--no-verdict"]))
        chosen.append(json.loads(model.read_text())["method"])
        log = work / f"log{lv}.csv"
        with open(log, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow([header[i] for i in out_cols])
            w.writerows([repr(float(v)) for v in row] for row in uc[held])
        out = work / f"forces{lv}.csv"
        summary = json.loads(run("apply", str(model), str(log), "-o", str(out), "--force",
                                 "--round-trip", "--json"))
        names = summary["force_columns"]
        oh, orows = read(out)
        got = np.array([[float(r[oh.index(n)]) for n in names] for r in orows])
        err["model"].append((got - f[held]) / fs)
        keep = ~held
        ct, *_ = np.linalg.lstsq(uc[keep], f[keep], rcond=None)
        err["matrix"].append((uc[held] @ ct - f[held]) / fs)
        cq, *_ = np.linalg.lstsq(squares(uc[keep]), f[keep], rcond=None)
        err["squares"].append((squares(uc[held]) @ cq - f[held]) / fs)
    rms = {m: np.sqrt((np.concatenate(e) ** 2).mean(axis=0)) for m, e in err.items()}
    return {"components": comps, **{m: r.tolist() for m, r in rms.items()},
            "ratio": float(rms["model"].max() / rms["matrix"].max()),
            "squares_ratio": float(rms["squares"].max() / rms["matrix"].max()),
            "chosen": chosen}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--file", type=Path, help="a rig file instead of simulated ones")
    ap.add_argument("--rig", default="lever-arm", help="simulate --rig: lever-arm or quadratic")
    ap.add_argument("--gauges", type=int, default=6, help="simulate --gauges: 8 for M > N")
    ap.add_argument("--limit", type=float, help="exit 1 when any file's ratio is above this")
    ap.add_argument("--method", default="auto", choices=["auto", "svr", "linear"],
                    help="fit --method in each fold (default auto, as issue 22's check)")
    ap.add_argument("--no-verdict", dest="verdict", action="store_false",
                    help="fit --no-verdict in each fold (not with auto, which needs it): the "
                         "model alone, at about half the cost")
    ap.add_argument("--in-process", action="store_true",
                    help="run the commands in this process (the same CLI, without starting "
                         "Python for each)")
    args = ap.parse_args(argv)
    cli = run_here if args.in_process else run
    if args.method == "auto" and not args.verdict:
        ap.error("--no-verdict: --method auto chooses by the held-out verdict; give --method svr")
    ratios = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in ([None] if args.file else args.seeds):
            work = Path(tmp) / f"s{seed}"
            work.mkdir()
            path = args.file
            if path is None:
                cli("simulate", str(work), "--rig", args.rig, "--seed", str(seed),
                    "--gauges", str(args.gauges))
                path = work / "calibration.csv"
            r = heldout(path, work, args.method, verdict=args.verdict, run=cli)
            ratios.append(r["ratio"])
            print(f"seed {seed}: worst RMS model {100 * max(r['model']):.3f} % F.S., matrix "
                  f"{100 * max(r['matrix']):.3f} % F.S., ratio {r['ratio']:.3f} (squared-terms "
                  f"least squares {r['squares_ratio']:.3f}); --method {args.method} kept "
                  f"{r['chosen'].count('svr')}/{len(r['chosen'])} folds' model")
    print(f"ratio over {len(ratios)} files: mean {np.mean(ratios):.3f}, max {np.max(ratios):.3f}")
    if args.limit is not None and max(ratios) > args.limit:
        raise SystemExit(1)


if __name__ == "__main__":
    main()
