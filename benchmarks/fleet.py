"""Benchmarks of issue 16 (fleets): many-log apply on both engines, and fit-many.

    python benchmarks/fleet.py            # 200 logs x 50,000 rows, 100 sensors, ~10 min
    python benchmarks/fleet.py --quick    # 40 logs x 20,000 rows, 8 sensors
    python benchmarks/fleet.py --docs     # also rewrite docs/benchmarks.md's fleet-benchmarks block
    python benchmarks/fleet.py --only parquet   # rows F1-F4 of one format, while iterating

Every target is a ratio against a baseline measured in the same run (medians of
``--repeats`` runs):

* ``apply`` of the logs as CSV files and as one partitioned Parquet dataset
  (a part per log), ``--engine dask`` on a LocalCluster of 2 worker processes
  against ``--engine local`` (the cluster's start-up is measured apart: it is
  paid once per cluster, not per run), and each engine against a pyarrow read and
  write of the same files (the streaming copy of run.py's rows 3 and 3c, file after
  file; a whole-file copy on pyarrow's threads is shown as info);
* the per-log overhead of each engine (one-row logs), for the scaling note;
* ``fit-many`` on simulated sensors against a sequential loop over the same sensors.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from run import ROOT, machine, median_time, publish, write_log  # noqa: E402  (puts ROOT and docs/ on sys.path)

from fsdecouple import load_calibration, load_config, load_model, save_model  # noqa: E402
from fsdecouple.fitting.fit import fit  # noqa: E402
from fsdecouple.logs.dask_engine import dask_client  # noqa: E402
from fsdecouple.logs.many import apply_many  # noqa: E402


def pyarrow_csv_copy(files, out: Path) -> None:
    """run.py's baseline of row 3 (PYARROW_CSV_COPY), file after file: a streaming copy."""
    import pyarrow.csv as pcsv

    for i, f in enumerate(files):
        r = pcsv.open_csv(f)
        with pcsv.CSVWriter(out / f"{i}.csv", r.schema) as w:
            for b in r:
                w.write_batch(b)


def pyarrow_parquet_copy(files, out: Path) -> None:
    """run.py's baseline of row 3c (PYARROW_PARQUET_COPY), file after file."""
    import pyarrow.parquet as pq

    for i, f in enumerate(files):
        pf = pq.ParquetFile(f)
        with pq.ParquetWriter(out / f"{i}.parquet", pf.schema_arrow) as w:
            for b in pf.iter_batches():
                w.write_batch(b)


def pyarrow_whole_csv_copy(files, out: Path) -> None:
    """A stricter baseline: whole files, read on pyarrow's threads."""
    import pyarrow.csv as pcsv

    for i, f in enumerate(files):
        pcsv.write_csv(pcsv.read_csv(f), out / f"{i}.csv")


def pyarrow_whole_parquet_copy(files, out: Path) -> None:
    import pyarrow.parquet as pq

    for i, f in enumerate(files):
        pq.write_table(pq.read_table(f), out / f"{i}.parquet")


def make_sensors(root: Path, n: int) -> Path:
    from fsdecouple.sim.simulate import simulate

    for i in range(n):
        d = root / f"s{i:03d}"
        simulate(d, seed=i)
        for extra in d.iterdir():  # only the calibration and the config
            if extra.is_file():
                extra.unlink()
        (d / "sensor.yaml").write_text("min_repetitions: 6\n")
    return root


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", type=int, help="logs (default 200, quick 40)")
    ap.add_argument("--rows", type=int, help="rows per log (default 50,000, quick 20,000)")
    ap.add_argument("--sensors", type=int, help="simulated sensors for fit-many (default 100, quick 8)")
    ap.add_argument("--repeats", type=int, help="runs per median (default 3)")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", choices=("csv", "parquet"),
                    help="only this format's rows F1-F4 (no F5-F7): for iterating, not for the docs")
    ap.add_argument("--docs", "--readme", dest="docs", action="store_true",
                    help="write the results into docs/benchmarks.md (between the fleet-benchmarks markers)")
    args = ap.parse_args()
    if args.only and args.docs:
        ap.error("--docs writes every row: drop --only")
    n_logs = args.logs or (40 if args.quick else 200)
    rows = args.rows or (20_000 if args.quick else 50_000)
    n_sensors = args.sensors or (8 if args.quick else 100)
    repeats = args.repeats or 3
    os.environ.setdefault("CI", "1")
    started = machine()
    results = []

    def row(target, value, unit, base, base_name, goal, ok):
        ratio = value / base
        results.append((target, value, unit, base, base_name, ratio, goal, ok))
        print(f"{target}: {value:.4g} {unit} vs {base:.4g} ({base_name}) = {ratio:.3g}  "
              f"[{goal}] {'PASS' if ok else 'FAIL'}", flush=True)

    import pyarrow.parquet as pq

    with tempfile.TemporaryDirectory(prefix="fsd-fleet-") as tmp_name:
        tmp = Path(tmp_name)
        settings = load_config()
        mfile = tmp / "model.json"
        save_model(fit(load_calibration(ROOT / "sample_data" / "calibration", settings), settings),
                   mfile)
        model = load_model(mfile)
        one = tmp / "one.csv"
        write_log(one, rows, model)
        csv_dir, ds = tmp / "csv", tmp / "ds"
        csv_dir.mkdir()
        ds.mkdir()
        import pyarrow.csv as pcsv
        table = pcsv.read_csv(one)
        for i in range(n_logs):
            shutil.copy(one, csv_dir / f"log{i:03d}.csv")
            pq.write_table(table, ds / f"part.{i}.parquet")
        csvs = sorted(csv_dir.iterdir())
        parts = sorted(ds.iterdir())
        total = n_logs * rows
        mb = sum(f.stat().st_size for f in csvs) / 1e6
        print(f"{n_logs} logs x {rows:,} rows ({mb:.0f} MB of CSV); {started}", flush=True)

        def run(inputs, engine, scheduler=None):
            out = tmp / f"out-{engine}"
            shutil.rmtree(out, ignore_errors=True)
            r = apply_many(mfile, inputs, out, engine=engine, scheduler=scheduler)
            assert not r.failed, r.failed[0].error

        def copy(fn, files):
            out = tmp / "copy"
            shutil.rmtree(out, ignore_errors=True)
            out.mkdir()
            fn(files, out)

        t0 = time.perf_counter()
        # the LocalCluster --engine dask starts without --scheduler (its workers' settings)
        stack = contextlib.ExitStack()
        client = stack.enter_context(dask_client(workers=2))
        client.wait_for_workers(2)
        address = client.scheduler.address
        warm = tmp / "warm"
        warm.mkdir()
        for i in range(4):  # the workers import fsdecouple, pandas and load the model once
            (warm / f"w{i}.csv").write_bytes(b"t,ux,uy,uz\n0,0.1,0,-0.1\n")
        run([warm], "dask", address)
        startup = time.perf_counter() - t0
        try:
            for kind, inputs, files, copier, whole in (
                    ("CSV", [csv_dir], csvs, pyarrow_csv_copy, pyarrow_whole_csv_copy),
                    ("Parquet", [ds], parts, pyarrow_parquet_copy, pyarrow_whole_parquet_copy)):
                if args.only not in (None, kind.lower()):
                    continue
                base = median_time(lambda files=files, copier=copier: copy(copier, files), repeats)
                strict = median_time(lambda files=files, whole=whole: copy(whole, files), repeats)
                local = median_time(lambda inputs=inputs: run(inputs, "local"), repeats)
                dask = median_time(lambda inputs=inputs: run(inputs, "dask", address), repeats)
                what = "logs" if kind == "CSV" else "parts of one dataset"
                row(f"F1. {kind}: --engine dask (2 workers) vs local, {n_logs} {what}", dask, "s",
                    local, "--engine local [s]", "<= 1.3x", dask / local <= 1.3)
                row(f"F2. {kind}: --engine local vs pyarrow", local, "s", base,
                    "pyarrow streaming read + write of the same files, as run.py [s]", "<= 1.5x",
                    local / base <= 1.5)
                row(f"F3. {kind}: --engine dask vs pyarrow", dask, "s", base,
                    "pyarrow streaming read + write, as run.py [s]", "<= 1.5x", dask / base <= 1.5)
                row(f"F3b. {kind}: --engine local vs whole-file pyarrow", local, "s", strict,
                    "pyarrow read_csv/read_table + write, on its threads [s]", "info", True)
                row(f"F4. {kind}: dask throughput per worker", total / dask / 2 / 1e6, "M rows/s",
                    total / local / 1e6, "local engine, 2 cores [M rows/s]", "info", True)
            if args.only is None:  # F5: the per-log overhead
                tiny = tmp / "tiny"
                tiny.mkdir()
                for i in range(n_logs):
                    (tiny / f"t{i:03d}.csv").write_bytes(b"t,ux,uy,uz\n0,0.1,0,-0.1\n")
                local_tiny = median_time(lambda: run([tiny], "local"), repeats) / n_logs
                dask_tiny = median_time(lambda: run([tiny], "dask", address), repeats) / n_logs
                row("F5. per-log overhead, dask (one-row logs)", dask_tiny * 1e3, "ms/log",
                    local_tiny * 1e3, "local engine [ms/log]", "info", True)
        finally:
            stack.close()
        if args.only is None:
            row("F6. LocalCluster(2 processes) start-up, workers' imports", startup, "s", dask,
                "one dask run, Parquet [s]", "info (paid once per cluster, not in F1)", True)

            from fsdecouple.fleet.sensors import fit_many, fit_sensor, sensor_dirs

            sensors = make_sensors(tmp / "sensors", n_sensors)
            seq_out, par_out = tmp / "models-seq", tmp / "models-par"
            seq_out.mkdir()
            t0 = time.perf_counter()
            for d in sensor_dirs(sensors):
                assert fit_sensor(d, seq_out, workers=1).error is None
            seq = time.perf_counter() - t0
            t0 = time.perf_counter()
            fleet = fit_many(sensors, par_out)
            par = time.perf_counter() - t0
            assert not fleet.failed
            row(f"F7. fit-many, {n_sensors} simulated sensors", par, "s", seq,
                "sequential loop of fit_sensor [s]", f"speed-up {seq / par:.2f}x (info)", True)

    return publish("fleet-benchmarks", f"Measured by `benchmarks/fleet.py` ({n_logs} logs x {rows:,} "
                   f"rows, {mb:.0f} MB of CSV; {n_sensors} sensors; {repeats} repeats): {started}",
                   results, args.docs)


if __name__ == "__main__":
    sys.exit(main())
