"""Nothing lost, nothing misread: apply's row contract, dialects, atomic outputs."""

from __future__ import annotations

import errno
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import SAMPLE, invoke, working_directory

from fsdecouple import load_config
from fsdecouple.core.modelfile import load_model
from fsdecouple.errors import InputError
from fsdecouple.files.outputs import atomic_write
from fsdecouple.logs.apply import STATUSES, apply_file

LOG = SAMPLE / "task_voltages.csv"


@pytest.fixture(scope="module")
def sample_model_file(sample_fit):
    """The suite's one sample fit (``fsdecouple fit sample_data/calibration``)."""
    return sample_fit[0] / "model.json"


@pytest.fixture(scope="module")
def sample_model(sample_model_file):
    return load_model(sample_model_file)


def forces(path, **kw):
    return pd.read_csv(path, dtype={"status": str}, keep_default_na=False, **kw)


# --- apply keeps every row ---------------------------------------------------------

def test_truncated_last_line_is_kept_and_flagged(tmp_path, sample_model_file):
    """A logger that crashed mid-write: the last line has no newline (and is short)."""
    text = LOG.read_text()
    cut = text[: text.rindex("\n") + 1] + "2.999,0.01"  # no newline, 2 of 4 fields
    log = tmp_path / "log.csv"
    log.write_text(cut)
    out = tmp_path / "f.csv"
    r = invoke(["apply", sample_model_file, log, "-o", out])
    f = forces(out)
    assert len(f) == 3001  # every input row, in order
    assert f["status"].iat[-1] == "truncated" and f["fx"].iat[-1] == ""
    assert "row 3002" in r.stderr and "truncated" in r.stderr
    assert (f["status"].iloc[:-1] != "truncated").all()


def test_last_line_without_newline_is_flagged_even_if_complete(tmp_path, sample_model_file):
    """All fields present but no newline: the last number may be cut short (0.01 of 0.0123)."""
    log = tmp_path / "log.csv"
    log.write_text(LOG.read_text().rstrip("\n"))
    out = tmp_path / "f.csv"
    invoke(["apply", sample_model_file, log, "-o", out])
    assert forces(out)["status"].iat[-1] == "truncated"


def test_blank_and_short_rows_are_kept_as_missing(tmp_path, sample_model_file):
    log = tmp_path / "log.csv"
    log.write_text("t,ux,uy,uz\n0,0.1,0.0,-0.1\n\n1,0.1\n2,0.2,0.1,-0.2\n3,5.0,0.0,0.0\n")
    out = tmp_path / "f.csv"
    r = invoke(["apply", sample_model_file, log, "-o", out])
    f = forces(out)
    assert f["t"].tolist() == ["0", "", "1", "2", "3"]
    assert f["status"].tolist() == ["ok", "missing", "missing", "ok", "extrapolated"]
    assert "2 rows have a missing voltage" in r.stderr and "rows 3, 4" in r.stderr
    assert "1 extrapolated" in r.stdout and set(f["status"]) <= set(STATUSES)


@pytest.mark.parametrize("eol", ["\n", "\r\n"])
def test_a_lone_blank_line_keeps_every_row_in_place(tmp_path, sample_model, eol):
    """A block that is numeric apart from one blank line: pyarrow skips the line, we must not."""
    lines = LOG.read_text().splitlines()
    lines.insert(1500, "")
    log = tmp_path / "log.csv"
    log.write_bytes(eol.join([*lines, ""]).encode())
    out = tmp_path / "f.csv"
    apply_file(sample_model, log, out, round_trip=True)
    f = pd.read_csv(out, dtype={"status": str}, keep_default_na=False, skip_blank_lines=False)
    assert len(f) == len(lines) - 1 and f["status"].iat[1499] == "missing"
    good = f.drop(index=1499)
    u = good[["ux", "uy", "uz"]].astype(float).to_numpy()
    np.testing.assert_allclose(good[["fx", "fy", "fz"]].astype(float), sample_model.decouple(u),
                               rtol=0, atol=1e-9)


def test_status_summary_counts_every_row(tmp_path, sample_model):
    out = tmp_path / "f.csv"
    s = apply_file(sample_model, LOG, out, tare=200)
    assert sum(s.status_counts.values()) == s.rows == 3000


def test_overflowing_voltages_are_flagged_not_nan_forces(tmp_path, sample_model):
    log = tmp_path / "log.csv"
    log.write_text("ux,uy,uz\n1e307,1e307,-1e307\n0.1,0,0\n")
    s = apply_file(sample_model, log, tmp_path / "f.csv")
    f = forces(tmp_path / "f.csv")
    assert f["status"].tolist() == ["not_finite", "ok"] and s.not_finite_rows == 1


# --- dialects: read correctly or refuse, never misread -------------------------------

def european(src, dst):
    dst.write_text("".join(
        ";".join(v.replace(".", ",") for v in line.split(",")) + "\r\n"
        for line in src.read_text().splitlines()
    ))


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_european_csv_through_the_config(tmp_path, sample_model_file):
    """sep ';' and decimal ',' (plus CRLF) give the same model and forces as the comma files."""
    cal = tmp_path / "cal"
    cal.mkdir()
    for f in (SAMPLE / "calibration").glob("*.csv"):
        european(f, cal / f.name)
    cfg = tmp_path / "eu.yaml"
    cfg.write_text("csv: {sep: ';', decimal: ','}\n")
    a, b = tmp_path / "eu.json", sample_model_file  # b: the model of the comma files
    invoke(["fit", cal, "-c", cfg, "-o", a, "--no-verdict"])  # the verdict is not compared
    da, db = json.loads(a.read_text()), json.loads(b.read_text())
    assert da["chi"] == db["chi"] and da["omega"] == db["omega"]
    log = tmp_path / "log.csv"
    european(LOG, log)
    fa, fb = tmp_path / "fa.csv", tmp_path / "fb.csv"
    invoke(["apply", a, log, "-o", fa, "--tare", "200"])  # the model's own dialect
    invoke(["apply", b, LOG, "-o", fb, "--tare", "200"])
    eu = pd.read_csv(fa, sep=";", decimal=",", dtype={"t": str})
    us = pd.read_csv(fb, dtype={"t": str})
    assert eu["t"].iat[5] == "0,005"  # input text passes through unchanged
    np.testing.assert_array_equal(eu[["fx", "fy", "fz"]], us[["fx", "fy", "fz"]])


@pytest.mark.parametrize("variant", ["bom", "crlf", "bom+crlf"])
@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_bom_and_windows_line_endings_read_correctly(tmp_path, variant, sample_model_file):
    cal = tmp_path / "cal"
    cal.mkdir()
    for f in (SAMPLE / "calibration").glob("*.csv"):
        text = f.read_text()
        if "crlf" in variant:
            text = text.replace("\n", "\r\n")
        (cal / f.name).write_bytes(("\ufeff" if "bom" in variant else "").encode() + text.encode())
    # every point read exactly as from the plain files (the tidy set, all but its file names)
    tidy = {}
    for name, src in (("bom", cal), ("plain", SAMPLE / "calibration")):
        invoke(["ingest", src, "-o", tmp_path / f"{name}.csv"])
        tidy[name] = pd.read_csv(tmp_path / f"{name}.csv", dtype=str).drop(columns="file")
    pd.testing.assert_frame_equal(tidy["bom"], tidy["plain"])
    m = sample_model_file
    if variant == "bom+crlf":  # and, once, the whole fit: the same chi as the plain files'
        m = tmp_path / "m.json"
        invoke(["fit", cal, "-o", m, "--no-verdict"])  # the held-out verdict is not compared
        assert json.loads(m.read_text())["chi"] == json.loads(sample_model_file.read_text())["chi"]
    log = tmp_path / "log.csv"
    log.write_bytes((SAMPLE / "task_voltages.csv").read_bytes().replace(b"\n", b"\r\n")
                    if "crlf" in variant else b"\xef\xbb\xbf" + LOG.read_bytes())
    fa, fb = tmp_path / "fa.csv", tmp_path / "fb.csv"
    invoke(["apply", m, log, "-o", fa, "--tare", "200"])
    invoke(["apply", m, LOG, "-o", fb, "--tare", "200"])
    assert fa.read_bytes() == fb.read_bytes()


# --- outputs: never overwrite without --force, never an input, always atomic --------

def test_existing_outputs_need_force(tmp_path, sample_model_file):
    for args in (["fit", SAMPLE / "calibration"], ["ingest", SAMPLE / "calibration"],
                 ["apply", sample_model_file, LOG]):
        out = tmp_path / "out"
        out.write_text("precious")
        r = invoke([*args, "-o", out], code=2)
        assert "already exists; pass --force" in r.stderr and out.read_text() == "precious"


def test_simulate_is_all_or_nothing(tmp_path):
    (tmp_path / "task_forces.csv").write_text("precious")
    r = invoke(["simulate", tmp_path], code=2)
    assert "task_forces.csv" in r.stderr and "--force" in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["task_forces.csv"]


@pytest.mark.parametrize("which", ["log", "model", "config"])
def test_output_that_is_an_input_is_refused_even_with_force(tmp_path, sample_model_file, which):
    log, m, cfg = tmp_path / "log.csv", tmp_path / "m.json", tmp_path / "c.yaml"
    shutil.copy(LOG, log)
    shutil.copy(sample_model_file, m)
    cfg.write_text("sensor: bench\n")
    target = {"log": log, "model": m, "config": cfg}[which]
    before = target.read_bytes()
    r = invoke(["apply", m, log, "-c", cfg, "-o", target, "--force"], code=2)
    assert "is also an input file" in r.stderr and target.read_bytes() == before


def test_fit_output_over_a_calibration_file_is_refused(tmp_path):
    cal = tmp_path / "cal"
    shutil.copytree(SAMPLE / "calibration", cal)
    before = (cal / "rep1.csv").read_bytes()
    r = invoke(["fit", cal, "-o", cal / "rep1.csv", "--force"], code=2)
    assert "is also an input file" in r.stderr and (cal / "rep1.csv").read_bytes() == before


def test_output_that_is_a_directory(tmp_path):
    r = invoke(["fit", SAMPLE / "calibration", "-o", tmp_path, "--force"], code=2)
    assert "is a directory" in r.stderr


def test_full_disk_leaves_previous_file_and_no_temporary(tmp_path):
    out = tmp_path / "forces.csv"
    out.write_text("previous")
    expected = "forces.csv: cannot write .*previous file is unchanged"
    with pytest.raises(InputError, match=expected), atomic_write(out) as fh:
        fh.write("half")
        raise OSError(errno.ENOSPC, "No space left on device")
    assert out.read_text() == "previous" and [p.name for p in tmp_path.iterdir()] == ["forces.csv"]


def test_interrupted_write_leaves_previous_file(tmp_path):
    out = tmp_path / "m.json"
    out.write_text("previous")
    with pytest.raises(KeyboardInterrupt), atomic_write(out) as fh:
        fh.write("half")
        raise KeyboardInterrupt
    assert out.read_text() == "previous" and [p.name for p in tmp_path.iterdir()] == ["m.json"]


# --- model files ----------------------------------------------------------------------

@pytest.mark.slow  # over ~0.8 s: the not-slow run stays under a minute
def test_refit_is_byte_identical_apart_from_created(tmp_path, sample_fit):
    """A second run of the suite's sample fit, in a directory laid out alike (so the
    calibration's paths are written alike), writes the same bytes but its time."""
    a, b = sample_fit[0] / "model.json", tmp_path / "model.json"
    (tmp_path / "sample_data").symlink_to(SAMPLE, target_is_directory=True)
    with working_directory(tmp_path):
        invoke(["fit", "sample_data/calibration", "-o", "model.json"])
    la, lb = a.read_text().splitlines(), b.read_text().splitlines()
    differ = [(x, y) for x, y in zip(la, lb, strict=True) if x != y]
    assert all('"created"' in x for x, _ in differ), differ


def test_only_safe_loaders_in_the_package():
    """No pickle, eval or unsafe YAML anywhere: inputs are data, never code."""
    import yaml

    import fsdecouple
    from fsdecouple.yamlfile import SafeUniqueLoader

    package = Path(fsdecouple.__file__).parent
    files = {p.relative_to(package).as_posix(): p.read_text() for p in package.rglob("*.py")}
    assert len(files) > 50  # every module, keyed by its path (names repeat across stages)
    src = "".join(files.values())
    import re

    # no generated source is run anywhere (core/ once exec'd its one-vector evaluator)
    assert not re.search(r"(?<![\w.])compile\(", src)
    for unsafe in ("import pickle", "pickle.", "eval(", "exec(", "unsafe_load", "full_load", "FullLoader",
                   "yaml.Loader", "UnsafeLoader", "marshal", "shelve"):
        assert unsafe not in src, unsafe
    assert issubclass(SafeUniqueLoader, yaml.SafeLoader)


def test_model_file_through_windows_git_still_loads(tmp_path, sample_model_file):
    """CRLF line endings and a BOM change bytes, not content: the digest still matches."""
    m = tmp_path / "m.json"
    m.write_bytes(b"\xef\xbb\xbf" + sample_model_file.read_bytes().replace(b"\n", b"\r\n"))
    out = tmp_path / "f.csv"
    invoke(["apply", m, LOG, "-o", out, "--tare", "200"])
    ref = tmp_path / "ref.csv"
    invoke(["apply", sample_model_file, LOG, "-o", ref, "--tare", "200"])
    assert out.read_bytes() == ref.read_bytes()


def test_a_log_without_line_ends_is_refused_not_read_into_memory(tmp_path):
    from fsdecouple.logs.reader import csv_bodies

    log = tmp_path / "log.csv"
    log.write_bytes(b"t,ux,uy,uz\n0,0.1,0,0\n" + b"1," * 5000)

    def bodies(max_line):
        with open(log, "rb") as fh:
            done = len(fh.readline())
            return list(csv_bodies(fh, log, done=done, total=None, chunk_rows=100, block_bytes=1024,
                                   max_line=max_line))

    with pytest.raises(InputError, match=r"log\.csv, row 3: no line end"):
        bodies(4096)
    assert len(bodies(1 << 20)) == 2


@pytest.mark.parametrize("cell", ["NAN", "-nan", "+nan", "nAn", "nan", "NaN", "NA", "na", "N/A",
                                  "null", "Null", ""])
def test_a_nan_cell_is_missing_whichever_reader_takes_its_block(tmp_path, sample_model, cell):
    """pyarrow reads the block unless something else in it (here a blank line) needs the
    line-by-line reader; a cell's status must not depend on its neighbours."""
    statuses = []
    for extra in ("", "\n"):
        log = tmp_path / "log.csv"
        log.write_text(f"t,ux,uy,uz\n0,0.1,0,-0.1\n1,{cell},0,0\n2,0.2,0,0\n{extra}")
        apply_file(sample_model, log, tmp_path / "f.csv", force=True)
        statuses.append(forces(tmp_path / "f.csv")["status"].tolist()[:3])
    assert statuses[0] == statuses[1] == ["ok", "missing", "ok"]


@pytest.mark.slow  # a subprocess run through a pipe, and a FIFO
def test_a_log_from_a_pipe_is_read_once_and_whole(sample_model_file, tmp_path):
    """`cat log | apply model -` and a FIFO give the same rows as the file: nothing dropped."""
    ref = tmp_path / "ref.csv"
    invoke(["apply", sample_model_file, LOG, "-o", ref, "--tare", "200"])
    piped = tmp_path / "piped.csv"
    run = subprocess.run(
        [sys.executable, "-m", "fsdecouple", "apply", str(sample_model_file), "-", "-o", str(piped),
         "--tare", "200"], input=LOG.read_bytes(), capture_output=True, check=False)
    assert run.returncode == 0, run.stderr.decode()
    assert piped.read_bytes() == ref.read_bytes()
    fifo = tmp_path / "log.fifo"
    os.mkfifo(fifo)
    out = tmp_path / "fifo.csv"
    # the FIFO is as much a pipe read in process (no second interpreter starting up)
    writer = subprocess.Popen(["sh", "-c", f"cat '{LOG}' > '{fifo}'"])
    invoke(["apply", sample_model_file, fifo, "-o", out, "--tare", "200"])
    writer.wait(timeout=60)
    assert out.read_bytes() == ref.read_bytes()


def test_scientific_notation_without_a_dot_is_a_number(tmp_path):
    """YAML 1.1 reads `1e-4` as text; a technician means the number (Table 2's epsilon)."""
    cfg = tmp_path / "c.yaml"
    cfg.write_text("svr: {epsilon: 1e-4, C: 1E3, tolerance: +1e-3}\n")
    s = load_config(cfg)
    assert (s.svr.epsilon, s.svr.C, s.svr.tolerance) == (1e-4, 1000.0, 1e-3)
    cfg.write_text("sensor: rig1e5\n")  # not a number: stays a name
    assert load_config(cfg).sensor == "rig1e5"


def test_a_log_of_many_side_columns_gets_a_short_warning(sim_model_file, tmp_path):
    """200,000 columns apply does not pass through (a repeated name) were named one by
    one: a 2 MB warning line.  The first 20 are named, the rest counted."""
    log = tmp_path / "wide.csv"
    log.write_text("t,ux,uy,uz" + ",c" * 20_000 + "\n0,0.1,0.2,0.3" + ",1" * 20_000 + "\n")
    r = invoke(["apply", sim_model_file, log, "-o", tmp_path / "o.csv"])
    line = next(x for x in r.stderr.splitlines() if "not passed through" in x)
    assert len(line) < 1000 and "5 'c', 6 'c'" in line and "24 'c' and 19,980 more" in line
