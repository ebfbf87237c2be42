"""All outputs of a command appear together or not at all; unwritable places are one line."""

from __future__ import annotations

import errno

import pytest
from conftest import SAMPLE, assert_one_line_error, invoke

from fsdecouple.files import outputs
from fsdecouple.sim import simulate as simulate_module


def test_simulate_failing_late_leaves_nothing(tmp_path, monkeypatch):
    """The repetition files are written, then the task fails: none of them, nor the dirs, stay."""
    def fail(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(simulate_module, "simulate_task", fail)
    out = tmp_path / "new" / "sim"
    assert_one_line_error(invoke(["simulate", out], code=2), "No space left")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("layout", ["paper", "lab"])
def test_simulate_output_appearing_meanwhile_takes_back_all(tmp_path, monkeypatch, layout):
    real = outputs.place
    last = "task_forces.csv" if layout == "paper" else "validation.csv"

    def racing(tmp, path, *, force):
        if path.name == last:
            path.write_text("theirs\n")
        return real(tmp, path, force=force)

    monkeypatch.setattr(outputs, "place", racing)
    assert_one_line_error(invoke(["simulate", tmp_path / "sim", "--layout", layout], code=2),
              last, "appeared while writing")
    left = sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*"))
    assert left == ["sim", f"sim/{last}"], left


def test_simulate_under_a_regular_file(tmp_path):
    (tmp_path / "afile").write_text("x")
    assert_one_line_error(invoke(["simulate", tmp_path / "afile" / "sub"], code=2), "afile")
    assert [p.name for p in tmp_path.iterdir()] == ["afile"]


def test_simulate_into_a_dir_holding_a_file_named_calibration(tmp_path):
    (tmp_path / "calibration").write_text("x")
    assert_one_line_error(invoke(["simulate", tmp_path], code=2), "calibration", "not a directory")
    assert [p.name for p in tmp_path.iterdir()] == ["calibration"]


def test_simulate_negative_seed():
    assert_one_line_error(invoke(["simulate", "never", "--seed", "-1"], code=2), "--seed -1")


@pytest.fixture(scope="module")
def model(sample_model):
    """conftest's sample_model: `fit` of sample_data/calibration, once a session."""
    return sample_model


def test_report_png_failure_creates_no_directory(tmp_path, model):
    cv = tmp_path / "cv.json"
    cv.write_text("{truncated")
    assert_one_line_error(invoke(["report", model, "--cv", cv, "-o", tmp_path / "r.html",
                      "--png", tmp_path / "figs" / "sub"], code=2), "cv.json")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cv.json"]


def test_report_png_that_looks_like_a_file(tmp_path, model):
    assert_one_line_error(invoke(["report", model, "-o", tmp_path / "r.html", "--png", tmp_path / "r2.html"],
                     code=2), "r2.html", "looks like a file name")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow  # renders the report figures
def test_report_and_pngs_together(tmp_path, model):
    invoke(["report", model, "-o", tmp_path / "r.html", "--png", tmp_path / "figs"])
    assert (tmp_path / "r.html").is_file() and len(list((tmp_path / "figs").glob("*.png"))) >= 2


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_read_only_directory_at_mkstemp(tmp_path, monkeypatch):
    """EROFS when the temporary file is created: one line, nothing written."""
    def erofs(*a, **k):
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(outputs.tempfile, "mkstemp", erofs)
    # --no-verdict: the output fails after the fit, whose held-out rounds are not what is tested
    assert_one_line_error(invoke(["fit", SAMPLE / "calibration", "-o", tmp_path / "m.json", "--no-verdict"],
                                 code=2), "m.json", "Read-only file system")
    assert list(tmp_path.iterdir()) == []


def test_read_only_directory_refused_before_work(tmp_path, monkeypatch):
    real = outputs.os.access
    monkeypatch.setattr(outputs.os, "access",
                        lambda p, mode, **k: p != tmp_path and real(p, mode, **k))
    assert_one_line_error(invoke(["fit", SAMPLE / "calibration", "-o", tmp_path / "m.json"], code=2),
              "m.json", "read-only filesystem or no permission")


@pytest.mark.parametrize("command", [
    ["fit", SAMPLE / "calibration"], ["export", "{model}"], ["report", "{model}"],
    ["validate", "{model}", SAMPLE / "calibration"], ["cv", SAMPLE / "calibration"],
    ["certificate", "{model}", SAMPLE / "calibration"], ["ingest", SAMPLE / "calibration"],
    ["init", SAMPLE / "loadcell" / "calibration.csv"],
])
def test_a_file_output_named_as_a_directory_is_refused(tmp_path, model, monkeypatch, command):
    """`-o report/` was written as a file named `report` (pathlib drops the slash, and a
    `/.`): every command that writes one file refuses a name that can only be a
    directory, before any work, and creates nothing (a usage error: one line and exit 2
    from the CLI's main, test_cli.py)."""
    monkeypatch.chdir(tmp_path)
    args = [str(model) if a == "{model}" else a for a in command]
    for name in ("out/", "out/.", "out/..", "."):
        r = invoke([*args, "-o", name], code=2)
        assert "'--output'" in r.stderr and f"'{name}' names a directory" in r.stderr, r.stderr
    assert list(tmp_path.iterdir()) == []


def test_apply_output_ending_in_slash_dot_is_the_many_log_form(tmp_path, model):
    """`apply M LOG -o forces/.` wrote a regular file `forces`, like `-o forces/` did once."""
    invoke(["apply", model, SAMPLE / "task_voltages.csv", "-o", f"{tmp_path / 'forces'}/."])
    assert (tmp_path / "forces" / "task_voltages.csv").is_file()


@pytest.mark.parametrize("command, suffix", [
    (["export", "{model}"], ".h"), (["init", SAMPLE / "loadcell" / "calibration.csv"], ".yaml"),
    (["apply", "{model}", SAMPLE / "task_voltages.csv"], ".parquet"),
])
def test_a_legal_255_byte_output_name_is_written(tmp_path, model, command, suffix):
    """`.NAME.XXXXXXXX.tmp` beside a 255-byte NAME is longer than a name may be: the
    output was refused ("File name too long").  The temporary's NAME is cut instead."""
    out = tmp_path / ("é" * 100 + "x" * (55 - len(suffix)) + suffix)  # 255 bytes in UTF-8
    assert len(out.name.encode()) == 255
    args = [str(model) if a == "{model}" else a for a in command]
    invoke([*args, "-o", out])
    invoke([*args, "-o", out, "--force"])  # over the first: the same temporary, cut
    assert out.is_file() and [p.name for p in tmp_path.iterdir()] == [out.name]
