"""Each bad input: one line naming file, row and column; exit 2; no output file."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest
from conftest import FAST_CONFIG, ROOT, SAMPLE, invoke

CAL = SAMPLE / "calibration"


@pytest.fixture
def cal(tmp_path):
    d = tmp_path / "cal"
    shutil.copytree(CAL, d)
    return d


def edit(path, row, col, value):
    """Set one cell (row as a spreadsheet counts: header = 1)."""
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    cells = lines[row - 1].split(",")
    cells[header.index(col)] = value
    lines[row - 1] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")


def fails(args, tmp_path, *needles):
    out = tmp_path / "out.json"
    r = invoke([*args, "-o", out], code=2)
    msg = r.stderr.strip()
    assert msg.startswith("error:") and len(msg.splitlines()) == 1, msg
    assert "Traceback" not in r.stderr + r.stdout
    for n in needles:
        assert n in msg, (n, msg)
    assert not out.exists()
    assert not list(tmp_path.glob(".out.json.*"))
    return msg


def test_missing_directory(tmp_path):
    fails(["fit", tmp_path / "nope"], tmp_path, "nope", "not found")


def test_missing_column(cal, tmp_path):
    p = cal / "rep2.csv"
    p.write_text(p.read_text().replace("uy", "u_y", 1))
    fails(["fit", cal], tmp_path, "rep2.csv", "row 1", "missing column 'uy'")


def test_non_numeric_cell(cal, tmp_path):
    edit(cal / "rep3.csv", 17, "uy", "n/a")
    fails(["fit", cal], tmp_path, "rep3.csv", "row 17", "column 'uy'", "'n/a'")


@pytest.mark.parametrize("value", ["nan", "inf"])
def test_nan_inf_empty(cal, tmp_path, value):
    edit(cal / "rep1.csv", 5, "fx", value)
    fails(["fit", cal], tmp_path, "rep1.csv", "row 5", "column 'fx'")


def test_a_blank_load_cell_is_skipped_or_refused_with_strict(cal, tmp_path):
    # issue 32: a load not typed in skips its row with a warning; --strict refuses it
    edit(cal / "rep1.csv", 5, "fx", "")
    r = invoke(["fit", cal, "-c", FAST_CONFIG, "-o", tmp_path / "m.json", "--no-verdict"])
    assert "rep1.csv, line 5: an applied load is blank" in r.stderr
    fails(["fit", cal, "--strict"], tmp_path, "rep1.csv", "row 5", "column 'fx'", "--strict")


def test_a_row_contradicting_its_own_axis_label_is_refused_and_excludable(cal, tmp_path):
    """Issue 34: in a single-axis file with an axis column, an x row with fy = 10 is a
    data-entry error, not a lever arm: refused naming the file, the row and both loads;
    ``--exclude`` drops it."""
    edit(cal / "rep4.csv", 3, "fy", "10.000")
    fails(["fit", cal, "--no-verdict"], tmp_path, "rep4.csv, row 3", "'x' sweep",
          "fx = -90", "fy = 10", "--exclude rep4.csv:3")
    r = invoke(["fit", cal, "-c", FAST_CONFIG, "-o", tmp_path / "m.json", "--no-verdict",
                "--exclude", "rep4.csv:3"])
    assert "several components" not in r.stderr


@pytest.mark.slow  # over ~0.8 s: the not-slow run stays under a minute
def test_row_loading_two_axes_is_fitted_jointly_and_named(cal, tmp_path):
    """Issue 22: without axis labels such a row may be a lever arm's or a multi-axis
    rig's, fitted, not refused; the warning names it, in case it is a typo."""
    for p in cal.glob("rep*.csv"):  # the same set without its axis column
        p.write_text("\n".join(ln.split(",", 1)[1] for ln in p.read_text().splitlines()) + "\n")
    edit(cal / "rep4.csv", 3, "fy", "10.000")
    r = invoke(["fit", cal, "-c", FAST_CONFIG, "-o", tmp_path / "m.json", "--no-verdict"])
    assert "1 row loads several components (" in r.stderr
    assert "rep4.csv, row 3): fitted jointly" in r.stderr


def test_sweep_without_zero_load_row(cal, tmp_path):
    p = cal / "rep5.csv"
    lines = p.read_text().splitlines()
    lines = [ln for ln in lines if not (ln.startswith("y,") and ln.split(",")[2] == "0.000")]
    p.write_text("\n".join(lines) + "\n")
    fails(["fit", cal], tmp_path, "rep5.csv", "y sweep of repetition 5", "no zero-load row")


def test_fewer_repetitions_than_config_requires(cal, tmp_path):
    (cal / "rep6.csv").unlink()
    fails(["fit", cal], tmp_path, "5 repetitions", "at least 6")


def test_bad_config_key(tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("ful_scale: {x: 1, y: 1, z: 1}\n")
    fails(["fit", CAL, "-c", cfg], tmp_path, "c.yaml", "unknown key 'ful_scale'",
          "did you mean 'full_scale'")


def test_negative_full_scale(tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("full_scale: {x: 100, y: -100, z: 150}\n")
    fails(["fit", CAL, "-c", cfg], tmp_path, "full_scale: y", "greater than 0")


def test_model_of_another_format(tmp_path):
    bad = tmp_path / "m.json"
    bad.write_text(json.dumps({"format": "something.else"}))
    fails(["apply", bad, SAMPLE / "task_voltages.csv"], tmp_path, "not an fsdecouple model")


def test_voltage_log_missing_column(tmp_path, sample_model):
    m = sample_model  # conftest: `fit` of sample_data/calibration, once a session
    log = tmp_path / "log.csv"
    log.write_text("t,ux,uy\n0,0.1,0.2\n")
    fails(["apply", m, log], tmp_path, "log.csv", "missing column 'uz'")


def test_voltage_log_non_numeric(tmp_path, sample_model):
    m = sample_model
    log = tmp_path / "log.csv"
    log.write_text("t,ux,uy,uz\n0,0.1,0.2,0.3\n1,0.1,abc,0.3\n")
    fails(["apply", m, log], tmp_path, "log.csv", "row 3", "column 'uy'", "'abc'")


def test_existing_output_not_overwritten_without_force(tmp_path):
    out = tmp_path / "out.json"
    out.write_text("precious")
    r = invoke(["fit", CAL, "-o", out], code=2)
    assert "--force" in r.stderr and out.read_text() == "precious"


@pytest.mark.slow  # a cv in a subprocess, through the CLI's main
def test_no_numpy_warning_from_a_pool_thread_after_the_error(tmp_path):
    """cv --workers 2 with a gross error of 1e308: the error restored the warning filters
    while the pool's other threads were still summing, and they printed numpy's overflow
    warnings under the error line.  Now the filter holds for the whole process."""
    import os
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", "fsdecouple", "cv", str(SAMPLE / "calibration"),
                        "--gross-error", "x:1:1:1e308", "--workers", "2", "-o", str(tmp_path / "cv.json")],
                       capture_output=True, text=True, timeout=300,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert r.returncode == 2 and len(r.stderr.splitlines()) == 1, r.stderr
    assert "RuntimeWarning" not in r.stderr and "too large" in r.stderr


@pytest.mark.parametrize("args", [
    ["apply", "{m}", SAMPLE / "task_voltages.csv", "--tare", "\u0663"],
    ["apply", "{m}", SAMPLE / "task_voltages.csv", "--zero", "\u0660,\u0660,\u0660"],
    ["cv", CAL, "--folds", "\u0661,\u0662;\u0663,\u0664;\u0665,\u0666"],
    ["fit", CAL, "--exclude", "rep1.csv:\u0663", "--no-verdict"],
    ["cv", CAL, "--gross-error", "x:\u0661:5:0.2"],
    ["fit", CAL, "--tune", "--tune-grid", "gamma=\u0661"],
])
def test_numbers_in_other_scripts_digits_are_refused(sample_model, tmp_path, args):
    """Issue 34: int() reads '\u0663' (Arabic-Indic three) as 3; --tare took it as 3 rows."""
    out = tmp_path / "out"
    r = invoke([str(a).format(m=sample_model) for a in args] + ["-o", out], code=2)
    # in-process the usage error is click's own text; the command prints it as one line
    assert "not an ASCII digit" in r.stderr or "valid integer" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr and not out.exists()


@pytest.mark.parametrize("tare", [["--tare", "\u0663"], ["--tare=\u0663"]])
def test_another_scripts_digit_is_refused_naming_the_option(sample_model, tmp_path, tare):
    """The refusal named neither the option nor the command ('fsdecouple: Invalid value:
    ...'), and '--tare=\u0663' was read as 3 rows, in silence."""
    out = tmp_path / "out.csv"
    r = subprocess.run([sys.executable, "-m", "fsdecouple", "apply", str(sample_model),
                        str(SAMPLE / "task_voltages.csv"), *tare, "-o", str(out)],
                       capture_output=True, text=True, timeout=120,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert r.returncode == 2 and not out.exists(), r.stderr
    assert len(r.stderr.splitlines()) == 1 and r.stderr.rstrip().endswith(
        "fsdecouple apply: Invalid value for '--tare': '\u0663' (U+0663) is not an ASCII digit "
        "0-9 (see 'python -m fsdecouple apply --help')"), r.stderr


def test_a_file_name_that_is_not_utf8_is_read_and_shown_with_its_byte(cal, tmp_path):
    """Issue 34: legal on Linux (a Latin-1 file share), it was refused ('rename the file').
    It is read, its repetition is its place in the set (rep3 as before), and messages and
    the model file show the byte as \\xff."""
    import os

    latin = os.path.join(os.fsencode(cal), b"rep3\xff.csv")
    os.rename(os.path.join(os.fsencode(cal), b"rep3.csv"), latin)
    out = tmp_path / "m.json"
    invoke(["fit", cal, "-c", FAST_CONFIG, "-o", out, "--no-verdict"])
    files = [f["path"] for f in json.loads(out.read_text())["provenance"]["files"]]
    assert files[2].endswith("rep3\\xff.csv") and len(files) == 6, files
    with open(latin, "rb") as fh:
        lines = fh.read().split(b"\n")
    cells = lines[4].split(b",")
    cells[5] = b"n/a"
    lines[4] = b",".join(cells)
    with open(latin, "wb") as fh:
        fh.write(b"\n".join(lines))
    fails(["fit", cal, "--no-verdict"], tmp_path, "rep3\\xff.csv, row 5, column 'uy'")


@pytest.mark.parametrize("command", [["apply", "{m}", SAMPLE / "task_voltages.csv"],
                                     ["fit", SAMPLE / "calibration", "--no-verdict"]])
def test_an_output_named_dash_is_refused_not_written_as_a_file(sample_model, tmp_path,
                                                               command):
    """'-' reads standard input; as -o it wrote a file named '-' in silence."""
    from conftest import working_directory

    with working_directory(tmp_path):
        r = invoke([str(a).format(m=sample_model) for a in command] + ["-o", "-"], code=2)
    assert "not to standard output" in r.stderr and not (tmp_path / "-").exists()
