"""Hostile sizes: every input kind has a limit checked before reading; messages quote
at most an excerpt and stay on one line; memory stays bounded."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from conftest import ROOT, SAMPLE, assert_one_line_error, invoke
from typer.testing import CliRunner

from fsdecouple.cli import app
from fsdecouple.errors import excerpt, printable, where
from fsdecouple.files.inputs import CONFIG_LIMIT, CV_LIMIT, MODEL_LIMIT

pytestmark = pytest.mark.slow  # measures peak memory of subprocesses on hostile inputs

CAL = SAMPLE / "calibration"


def _sparse(path, size=1 << 30):
    with open(path, "wb") as f:
        f.truncate(size)
    return path




def _commands(path, good_model, out):
    return {
        "config": ["fit", CAL, "-c", path, "-o", out],
        "model": ["show", path],
        "cv": ["report", good_model, "--cv", path, "-o", out],
    }


@pytest.fixture(scope="module")
def good_model(sample_model):
    return sample_model  # the suite's sample fit: the commands below only read it


@pytest.mark.parametrize("kind", ["config", "model", "cv"])
def test_sparse_gigabyte_is_refused_before_reading(tmp_path, good_model, kind):
    big = _sparse(tmp_path / "big.json")
    out = tmp_path / "out.html"
    r = invoke(_commands(big, good_model, out)[kind], code=2)
    assert_one_line_error(r, "big.json", "1024 MB", "limit", "not read")
    assert not out.exists()


@pytest.mark.parametrize("kind", ["config", "model", "cv"])
def test_dev_zero_is_read_to_the_limit_only(tmp_path, good_model, kind):
    out = tmp_path / "out.html"
    r = invoke(_commands("/dev/zero", good_model, out)[kind], code=2)
    assert_one_line_error(r, "/dev/zero", "more than the", "limit")
    assert not out.exists()


def test_limits_are_as_documented():
    readme = (ROOT / "docs" / "errors.md").read_text(encoding="utf-8")
    assert (CONFIG_LIMIT, MODEL_LIMIT, CV_LIMIT) == (1 << 20, 64 << 20, 64 << 20)
    for text in ("1 MB", "64 MB"):
        assert text in readme


def test_config_just_over_the_limit(tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("# " + "x" * CONFIG_LIMIT + "\n")
    assert_one_line_error(invoke(["fit", CAL, "-c", cfg, "-o", tmp_path / "m.json"], code=2),
              "c.yaml", "larger than the 1 MB limit for a config file")


def test_big_csv_as_config_quotes_an_excerpt(tmp_path):
    """`-c data.csv` under the limit: the message quotes the start of the file only."""
    cfg = tmp_path / "data.csv"
    cfg.write_text("t,ux,uy,uz\n" + "0,0.1,0.2,0.3\n" * 50_000)
    msg = assert_one_line_error(invoke(["fit", CAL, "-c", cfg, "-o", tmp_path / "m.json"], code=2),
                    "data.csv", "expected a mapping")
    assert len(msg) < 300, len(msg)


def _maxrss_kb(args):
    """Run the CLI in a fresh interpreter; its exit code, stderr and peak RSS [kB].

    The peak is the process's own VmHWM: getrusage's ru_maxrss survives exec, so a
    child forked from a large pytest process would report the parent's peak.
    """
    code = textwrap.dedent(f"""
        import sys
        sys.argv = ["fsdecouple", *{[str(a) for a in args]!r}]
        from fsdecouple.cli import main
        try:
            main()
        finally:
            hwm = next(line for line in open("/proc/self/status") if line.startswith("VmHWM"))
            print("MAXRSS", hwm.split()[1], file=sys.stderr)
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120)
    lines = r.stderr.strip().splitlines()
    return r.returncode, lines[:-1], int(lines[-1].split()[1])


@pytest.mark.parametrize("source", ["/dev/zero", "sparse"])
@pytest.mark.parametrize("kind", ["config", "model", "cv"])
def test_memory_stays_bounded(tmp_path, good_model, kind, source):
    path = "/dev/zero" if source == "/dev/zero" else _sparse(tmp_path / "big.json")
    code, lines, rss = _maxrss_kb(_commands(path, good_model, tmp_path / "o.html")[kind])
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error:"), lines
    assert rss < 500_000, f"{rss} kB"


def test_alias_bomb_is_quick_and_small(tmp_path):
    cfg = tmp_path / "bomb.yaml"
    levels = ["a: &a [x, x, x, x, x, x, x, x, x]"]
    for prev, name in zip("abcdefgh", "bcdefghi", strict=True):
        levels.append(f"{name}: &{name} [{', '.join(['*' + prev] * 9)}]")
    cfg.write_text("\n".join(levels) + "\n")
    code, lines, rss = _maxrss_kb(["fit", CAL, "-c", cfg, "-o", tmp_path / "m.json"])
    assert code == 2 and "aliases are expanded" in lines[0], lines
    assert rss < 500_000


def test_json_nested_deep_in_cv(tmp_path, good_model):
    cv = tmp_path / "cv.json"
    cv.write_text("[" * 100_000 + "]" * 100_000)
    assert_one_line_error(invoke(["report", good_model, "--cv", cv, "-o", tmp_path / "r.html"], code=2),
              "cv.json", "too deeply nested")


def test_file_name_with_a_newline_staysassert_one_line_error(tmp_path, good_model):
    bad = tmp_path / "two\nlines.json"
    bad.write_text("{not json")
    msg = assert_one_line_error(invoke(["show", bad], code=2), "two\\nlines.json")
    cfg = tmp_path / "c\n.yaml"
    assert_one_line_error(invoke(["fit", CAL, "-c", cfg, "-o", tmp_path / "m.json"], code=2), "c\\n.yaml")
    assert msg


def test_excerpt_and_printable():
    assert excerpt("x" * 100, 10) == "xxxxxxxxxx... (100 characters)"
    assert excerpt("short") == "short"
    assert printable("a\nb\tc\x1bd é") == "a\\nb\\tc\\x1bd é"
    assert where("r\n.csv", 3, "u\ny") == "r\\n.csv, row 3, column 'u\\ny'"
    # a name's non-UTF-8 byte is shown as that byte, as a path's is: s\xff, not s\udcff
    assert printable(os.fsdecode(b"s\xff")) == "s\\xff"


def test_numpy_warnings_are_not_printed_before_an_error(tmp_path, good_model):
    """A log near 1e308 overflows in numpy: only the command's own lines reach stderr."""
    log = tmp_path / "huge.csv"
    log.write_text("t,ux,uy,uz\n0,1e308,1e308,-1e308\n1,1e308,1e308,1e308\n")
    r = CliRunner().invoke(app, ["apply", str(good_model), str(log), "-o", str(tmp_path / "f.csv")])
    assert "RuntimeWarning" not in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert r.exit_code in (0, 2)
    if r.exit_code == 2:
        assert len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_a_nul_padded_calibration_file_is_refused_small(tmp_path):
    """A 50 MB NUL-padded repetition once gave a 210 MB error and 1.5 GB of memory."""
    cal = tmp_path / "cal"
    shutil.copytree(CAL, cal)
    with open(cal / "rep1.csv", "ab") as fh:
        fh.write(b"\x00" * 50_000_000)
    code, lines, rss = _maxrss_kb(["ingest", cal])
    assert code == 2 and len(lines) == 1 and "NUL byte" in lines[0] and len(lines[0]) < 300
    assert rss < 500_000, f"{rss} kB"


@pytest.mark.parametrize("args, needle", [
    (["simulate", "{tmp}/s", "--repetitions", "1000000000"], "from 1 to 1000"),
    (["simulate", "{tmp}/s", "--layout", "lab", "--levels", "100000000"], "from 1 to 10000"),
    (["simulate", "{tmp}/s", "--components", "6", "--repetitions", "5000"], "from 1 to 1000"),
    (["cv", "{cal}", "--folds", ";".join(["1,2"] * 3000)], "3000 rounds; at most 100"),
    (["cv", "{cal}", "--repeats", "1000000"], "1 to 100 timing passes"),
])
def test_counts_have_documented_bounds(tmp_path, args, needle):
    """--repetitions 1e9 and --levels 1e8 ran until the memory was gone; --folds with 3000
    rounds was accepted.  Each count has a bound, refused before any work."""
    args = [a.format(tmp=tmp_path, cal=SAMPLE / "calibration") for a in args]
    assert_one_line_error(invoke(args, code=2), needle)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(not Path("/dev/zero").exists(), reason="no /dev/zero")
def test_a_task_log_has_a_size_limit():
    """cv --task /dev/zero grew to 13-23 GB before it was killed."""
    r = invoke(["cv", SAMPLE / "calibration", "--task", "/dev/zero", "--task-forces",
                SAMPLE / "task_forces.csv"], code=2)
    assert_one_line_error(r, "/dev/zero", "limit for a task log")
