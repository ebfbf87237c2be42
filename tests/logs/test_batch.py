"""Many-log apply (issue 16): inputs, outputs, per-log errors, the local engine.

Every output is checked against single-file ``apply`` of the same log, which the
rest of the suite checks against the paper's eq. (11); the Dask engine's tests are
in test_batch_dask.py.
"""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import ROOT, SAMPLE, assert_one_line_error, invoke

LOG = SAMPLE / "task_voltages.csv"


def make_logs(root):
    """logs/a/one.csv, logs/b/two.csv (rows 2-1001 of the sample log), logs/ds/ (the sample
    log cut into three Parquet parts), logs/single.parquet, and a README that is no log."""
    lines = LOG.read_text().splitlines(keepends=True)
    (root / "logs" / "a").mkdir(parents=True)
    (root / "logs" / "b").mkdir()
    shutil.copy(LOG, root / "logs" / "a" / "one.csv")
    (root / "logs" / "b" / "two.csv").write_text("".join([lines[0], *lines[2:1002]]))
    (root / "logs" / "README.txt").write_text("not a log\n")
    table = pa.Table.from_pandas(__import__("pandas").read_csv(LOG), preserve_index=False)
    (root / "logs" / "ds").mkdir()
    for i, (a, b) in enumerate(((0, 1000), (1000, 2200), (2200, 3000))):
        pq.write_table(table.slice(a, b - a), root / "logs" / "ds" / f"part.{i}.parquet")
    pq.write_table(table, root / "logs" / "single.parquet")
    return root / "logs"


def spoil(logs):
    """Two bad inputs among the good: a text value in two.csv (row 6, uy), and a dataset part
    without uz."""
    text = (logs / "b" / "two.csv").read_text().splitlines()
    text[5] = "0.004,0.01,abc,0.0"
    (logs / "b" / "two.csv").write_text("\n".join(text) + "\n")
    pq.write_table(pa.table({"t": [0.0], "ux": [0.1], "uy": [0.0]}), logs / "ds" / "part.3.parquet")
    return logs


def single(model, log, out, *args):
    invoke(["apply", model, log, "-o", out, *args])
    return out


def test_a_directory_is_every_log_under_it_each_as_single_file_apply(sample_model, tmp_path):
    logs = make_logs(tmp_path)
    out = tmp_path / "out"
    r = invoke(["apply", sample_model, logs, "-o", f"{out}/", "--tare", 200, "--json"])
    doc = json.loads(r.stdout)
    assert doc["format"] == "fsdecouple.apply_many" and doc["failed"] == []
    got = {f["input"]: f for f in doc["files"]}
    assert set(got) == {str(logs / p) for p in ("a/one.csv", "b/two.csv", "ds", "single.parquet")}
    # CSV: the bytes of single-file apply, tare per log
    for rel in ("a/one.csv", "b/two.csv"):
        ref = single(sample_model, logs / rel, tmp_path / "ref.csv", "--tare", 200, "--force")
        assert (out / rel).read_bytes() == ref.read_bytes(), rel
    assert got[str(logs / "b/two.csv")]["rows"] == 1000
    assert got[str(logs / "a/one.csv")]["status_counts"]["ok"] == 3000
    # the dataset: its parts decoupled with the zero of its first 200 rows, so the parts
    # together are the whole log decoupled as one file
    ref = pq.read_table(single(sample_model, logs / "single.parquet", tmp_path / "ref.parquet",
                               "--tare", 200))
    assert sorted(p.name for p in (out / "ds").iterdir()) == [f"part.{i}.parquet" for i in range(3)]
    parts = pa.concat_tables(pq.read_table(out / "ds" / f"part.{i}.parquet") for i in range(3))
    assert parts.equals(ref)
    assert pq.read_table(out / "single.parquet").equals(ref)
    assert pq.read_schema(out / "ds" / "part.1.parquet").metadata[b"fsdecouple.force_unit"] == b"N"
    assert not (out / "README.txt").exists()
    assert sorted(p.name for p in out.iterdir()) == ["a", "b", "ds", "single.parquet"]  # no staging


def test_files_and_globs_go_under_their_common_parent(sample_model, tmp_path):
    logs = make_logs(tmp_path)
    out = tmp_path / "out"
    r = invoke(["apply", sample_model, logs / "a" / "one.csv", str(logs / "b" / "*.csv"),
                "-o", out / "", "--unit", "gf"])
    assert "forces in gf" in r.stdout and "a/one.csv" in r.stdout
    assert sorted(str(p.relative_to(out)) for p in out.rglob("*.csv")) == ["a/one.csv", "b/two.csv"]
    ref = single(sample_model, logs / "a" / "one.csv", tmp_path / "ref.csv", "--unit", "gf")
    assert (out / "a" / "one.csv").read_bytes() == ref.read_bytes()


@pytest.mark.skipif(not Path("/dev/fd").is_dir(), reason="needs /dev/fd")
def test_a_piped_log_is_named_as_given_and_leaves_the_files_where_they_were(tmp_path):
    """/dev/stdin or <(...) beside a file resolved to /proc/PID/fd/pipe:[N]: the file went to
    OUT/tmp/.../one.csv and the pipe to OUT/proc/PID/fd/pipe:[N]."""
    import os

    from fsdecouple.logs.many import find_jobs

    logs = make_logs(tmp_path)
    r, w = os.pipe()
    try:
        jobs, _ = find_jobs([logs / "a" / "one.csv", f"/dev/fd/{r}"])
    finally:
        os.close(r)
        os.close(w)
    assert [str(j.rel) for j in jobs] == ["one.csv", f"{r}.csv"]


def test_a_bad_log_is_reported_and_does_not_stop_the_others(sample_model, tmp_path):
    logs = spoil(make_logs(tmp_path))
    out = tmp_path / "out"
    r = invoke(["apply", sample_model, logs, "-o", f"{out}/", "--json"], code=2)
    doc = json.loads(r.stdout)
    assert doc["failed"] == [str(logs / "b" / "two.csv"), str(logs / "ds")]
    errors = r.stderr.strip().splitlines()
    assert len(errors) == 2 and all(e.startswith("error: ") for e in errors), r.stderr
    assert "two.csv, row 6, column 'uy'" in errors[0] and "part.3.parquet" in errors[1]
    assert (out / "a" / "one.csv").is_file() and (out / "single.parquet").is_file()
    assert not (out / "b").exists() and not (out / "ds").exists()  # nothing of the failed ones
    assert sorted(p.name for p in out.iterdir()) == ["a", "single.parquet"]


def test_existing_outputs_need_force_a_dataset_is_replaced_whole(sample_model, tmp_path):
    logs = make_logs(tmp_path)
    out = tmp_path / "out"
    invoke(["apply", sample_model, logs / "ds", "-o", f"{out}/"])
    (out / "ds" / "part.9.parquet").write_text("stale")
    r = invoke(["apply", sample_model, logs / "ds", "-o", f"{out}/"], code=2)
    assert "already exists; pass --force" in r.stderr
    assert (out / "ds" / "part.9.parquet").read_text() == "stale"
    invoke(["apply", sample_model, logs / "ds", "-o", f"{out}/", "--force"])
    assert sorted(p.name for p in (out / "ds").iterdir()) == [f"part.{i}.parquet" for i in range(3)]


@pytest.mark.parametrize("case", ["empty glob", "empty dir", "out is the input dir", "out inside it",
                                  "out is an input", "missing", "scheduler without dask engine",
                                  "engine for a single file", "unknown engine", "clash"])
def test_bad_input_is_one_line_and_writes_nothing(sample_model, tmp_path, case):
    logs = make_logs(tmp_path)
    out = tmp_path / "out"
    (tmp_path / "empty").mkdir()
    (tmp_path / "x").mkdir()
    shutil.copy(LOG, tmp_path / "x" / "one.csv")  # x/one.csv -> OUT/one.csv, as logs/a/one.csv
    args, needle = {
        "empty glob": ([str(logs / "*.nothing")], "matches no .csv or .parquet log"),
        "empty dir": ([tmp_path / "empty"], "a directory with no .csv or .parquet log"),
        "out is the input dir": ([logs, "-o", logs], "is the input directory"),
        "out inside it": ([logs, "-o", logs / "forces"], "is the input directory"),
        "out is an input": ([logs / "a" / "one.csv", logs / "b", "-o", logs / "a" / "one.csv"],
                            "is one of the inputs"),
        "missing": ([logs / "nope.csv", logs / "b"], "nope.csv: file not found"),
        "scheduler without dask engine": ([logs, "--scheduler", "tcp://127.0.0.1:1"],
                                          "give --engine dask"),
        "engine for a single file": ([LOG, "-o", out / "f.csv", "--engine", "dask"],
                                     "trailing /"),
        "unknown engine": ([logs, "--engine", "spark"], "--engine 'spark'"),
        "clash": ([logs / "a" / "one.csv", tmp_path / "x"], "would both be written"),
    }[case]
    if "-o" not in args:
        args = [*args, "-o", f"{out}/"]
    before = sorted(tmp_path.rglob("*"))
    assert_one_line_error(invoke(["apply", sample_model, *args], code=2), needle)
    assert sorted(tmp_path.rglob("*")) == before  # nothing written, not even the directory


def test_engine_dask_without_dask_says_what_to_install(sample_model, tmp_path, monkeypatch):
    logs = make_logs(tmp_path)
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    r = invoke(["apply", sample_model, logs, "-o", f"{tmp_path / 'out'}/", "--engine", "dask"],
               code=2)
    assert_one_line_error(r, "pip install 'fsdecouple[dask]'")
    assert not (tmp_path / "out").exists()




def make_six_axis_logs(root):
    """six/log.csv (the six-axis sample log), six/ds/ (it in three Parquet parts) and
    six/whole.parquet (it in one file): the same rows three ways."""
    import pandas as pd

    log = SAMPLE / "six_axis" / "task_voltages.csv"
    (root / "six" / "ds").mkdir(parents=True)
    shutil.copy(log, root / "six" / "log.csv")
    table = pa.Table.from_pandas(pd.read_csv(log), preserve_index=False)
    for i, (a, b) in enumerate(((0, 150), (150, 1200), (1200, table.num_rows))):
        pq.write_table(table.slice(a, b - a), root / "six" / "ds" / f"part.{i}.parquet")
    pq.write_table(table, root / "whole.parquet")
    return root / "six"


SIX_MODEL = ROOT / "tests" / "fixtures" / "golden" / "six-axis-v3.json"  # forces in N, moments in N·m


@pytest.mark.parametrize("how", [["--tare", 200], ["--zero", "0.01,-0.02,0,0.003,0,-0.001"]])
def test_six_axis_logs_and_datasets_get_all_six_components(tmp_path, how):
    """A six-axis model on many logs: every component written, and a dataset's tare read
    across its parts (the first part is shorter than the tare) as one log's would be."""
    model = SIX_MODEL
    logs = make_six_axis_logs(tmp_path)
    doc = json.loads(invoke(["apply", model, logs, "-o", f"{tmp_path / 'out'}/", *how,
                             "--json"]).stdout)
    assert [f["error"] for f in doc["files"]] == [None, None]
    whole = single(model, tmp_path / "whole.parquet", tmp_path / "whole-out.parquet", *how)
    want = pq.read_table(whole)
    got = pq.read_table(tmp_path / "out" / "ds")
    assert got.column_names == want.column_names
    assert {"fx", "fy", "fz", "mx", "my", "mz", "status"} <= set(got.column_names)
    assert got.equals(want.cast(got.schema))
    csv = single(model, logs / "log.csv", tmp_path / "log-out.csv", *how)
    assert (tmp_path / "out" / "log.csv").read_bytes() == csv.read_bytes()


def test_one_log_to_an_output_ending_in_a_slash_is_the_many_log_form(sample_model, tmp_path):
    """`-o forces/` wrote a regular file 'forces': the trailing / was lost on the way in."""
    out = tmp_path / "forces"
    invoke(["apply", sample_model, SAMPLE / "task_voltages.csv", "--tare", 200, "-o", f"{out}/"])
    assert out.is_dir() and (out / "task_voltages.csv").is_file()
    invoke(["apply", sample_model, SAMPLE / "task_voltages.csv", "-o", tmp_path / "f.csv"])
    assert (tmp_path / "f.csv").is_file()  # without the slash: one file, as before


def odd_entries(root: Path) -> Path:
    """A directory of one good log beside a FIFO, a dangling link and a directory, each
    named like a log."""
    import os

    logs = root / "odd"
    logs.mkdir()
    (logs / "good.csv").write_text((SAMPLE / "task_voltages.csv").read_text())
    os.mkfifo(logs / "fifo.csv")
    (logs / "dangling.csv").symlink_to(root / "nowhere.csv")
    (logs / "folder.csv").mkdir()
    return logs


def test_entries_named_like_logs_that_are_not_files_are_listed_as_failed(sample_model, tmp_path):
    """A FIFO, a dangling link or a directory named like a log was skipped with exit 0 and
    never listed: each is now a failed log (exit 2), named with what it is."""
    logs = odd_entries(tmp_path)
    r = invoke(["apply", sample_model, logs, "-o", f"{tmp_path / 'out'}/", "--json"], code=2)
    doc = json.loads(r.stdout)
    errors = {Path(f["input"]).name: f["error"] for f in doc["files"]}
    assert errors["good.csv"] is None and (tmp_path / "out" / "good.csv").is_file()
    assert "FIFO" in errors["fifo.csv"] and "link to nothing" in errors["dangling.csv"]
    assert "directory named like a log" in errors["folder.csv"]
    assert sorted(Path(p).name for p in doc["failed"]) == ["dangling.csv", "fifo.csv", "folder.csv"]


def test_a_symbolic_link_loop_named_like_a_log_is_listed_as_failed(sample_model, tmp_path):
    """`loop.csv -> loop.csv` in a directory of logs: Path.resolve raised RuntimeError, a
    traceback before any log was decoupled.  Now it is a failed log like a dangling link."""
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / "good.csv").write_text((SAMPLE / "task_voltages.csv").read_text())
    (logs / "loop.csv").symlink_to("loop.csv")
    r = invoke(["apply", sample_model, logs, "-o", f"{tmp_path / 'out'}/", "--json"], code=2)
    doc = json.loads(r.stdout)
    assert [Path(p).name for p in doc["failed"]] == ["loop.csv"]
    assert (tmp_path / "out" / "good.csv").is_file()


@pytest.mark.parametrize("command", ["apply", "fit-many"])
def test_an_output_directory_that_cannot_be_written_is_one_line(sample_model, tmp_path, monkeypatch,
                                                                command):
    """A read-only output directory was a PermissionError traceback in many-log apply and
    fit-many (tests run as root here, so the directory's refusal is simulated)."""
    import os as os_module

    out = tmp_path / "ro"
    out.mkdir()
    real = os_module.access
    def access(p, mode, **kw):  # readable, not writable
        return False if Path(p) == out and mode & os_module.W_OK else real(p, mode, **kw)

    monkeypatch.setattr(os_module, "access", access)
    if command == "apply":
        args = ["apply", sample_model, SAMPLE / "task_voltages.csv", "-o", f"{out}/"]
    else:
        sensor = tmp_path / "sensors" / "a"
        sensor.mkdir(parents=True)
        for f in (SAMPLE / "calibration").glob("rep*.csv"):
            (sensor / f.name).write_bytes(f.read_bytes())
        (sensor / "sensor.yaml").write_text("sensor: a\n")
        args = ["fit-many", tmp_path / "sensors", "-o", out]
    assert_one_line_error(invoke(args, code=2), "ro", "cannot write into it", "Permission denied")
    assert list(out.iterdir()) == []


def test_many_logs_take_interval_and_refuse_a_bad_one_before_reading(sample_model, tmp_path):
    """Issue 23: many-log apply adds the interval columns as single-file apply does (it
    refused --interval), and refuses P outside (0, 1) with one line, nothing written."""
    logs = make_logs(tmp_path)
    r = invoke(["apply", sample_model, logs, "-o", f"{tmp_path / 'bad'}/", "--interval", 1.5], 2)
    assert_one_line_error(r, "--interval: coverage 1.5")
    assert not (tmp_path / "bad").exists()
    invoke(["apply", sample_model, logs, "-o", f"{tmp_path / 'out'}/", "--tare", 200,
            "--interval", 0.95])
    one = single(sample_model, logs / "a" / "one.csv", tmp_path / "one.csv", "--tare", 200,
                 "--interval", 0.95)
    assert one.read_bytes() == (tmp_path / "out" / "a" / "one.csv").read_bytes()
    assert pq.read_table(tmp_path / "out" / "single.parquet").column_names[-7:] == [
        "fx_lo", "fx_hi", "fy_lo", "fy_hi", "fz_lo", "fz_hi", "status"]
