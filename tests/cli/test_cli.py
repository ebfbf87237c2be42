"""The command line, end to end, through CliRunner."""

from __future__ import annotations

import json
import os

import numpy as np
import pandas as pd
import pytest
from conftest import FAST_CONFIG, FAST_SVR, SAMPLE, invoke


@pytest.mark.slow  # over ~0.6 s: the not-slow run stays under a minute
def test_fit_apply_round_trip(tmp_path, sim_dir, sim_fit):
    model, r = sim_fit
    assert "Interference error gamma" in r.stdout and model.exists()
    doc = json.loads(model.read_text())
    assert doc["format"] == "fsdecouple.model" and len(doc["chi"]) == 6
    assert all(len(f["sha256"]) == 64 for f in doc["provenance"]["files"])
    out = tmp_path / "forces.csv"
    invoke(["apply", model, sim_dir / "task_voltages.csv", "-o", out, "--tare", "200"])
    forces = pd.read_csv(out)
    log = pd.read_csv(sim_dir / "task_voltages.csv", dtype=str)
    assert list(forces.columns) == [*log.columns, "fx", "fy", "fz", "status"]
    assert set(forces["status"]) <= {"ok", "extrapolated"}
    # input columns pass through as text, unchanged and in order
    pd.testing.assert_frame_equal(pd.read_csv(out, dtype=str)[list(log.columns)], log)
    truth = pd.read_csv(sim_dir / "task_forces.csv")
    err = np.abs(forces[["fx", "fy", "fz"]].to_numpy() - truth[["fx", "fy", "fz"]].to_numpy())
    assert err.max() < 0.75  # 0.5 % of 150 N, see test_task_forces_close_to_truth


def test_sample_data_is_the_simulator_output(tmp_path):
    """sample_data/ is exactly what `fsdecouple simulate sample_data` writes.

    (sample_data/loadcell/, written by `simulate --layout lab`, is compared in
    tests/test_simulate_lab.py.)
    """
    invoke(["simulate", tmp_path])
    for f in sorted(SAMPLE.rglob("*.csv")):
        rel = f.relative_to(SAMPLE)
        if rel.parts[0] not in ("loadcell", "six_axis"):  # six_axis: tests/test_six_axis.py
            assert (tmp_path / rel).read_bytes() == f.read_bytes(), rel


def test_ingest_summary_and_tidy_output(tmp_path):
    tidy = tmp_path / "tidy.csv"
    r = invoke(["ingest", SAMPLE / "calibration", "-o", tidy, "--json"])
    doc = json.loads(r.stdout)
    assert doc["repetitions"] == [1, 2, 3, 4, 5, 6]
    assert doc["axes"]["x"]["points"] == 126 and doc["axes"]["z"]["load_min"] == -150
    points = pd.read_csv(tidy)
    # zero-corrected: every sweep's zero-load rows now average 0
    zero = points[(points[["fx", "fy", "fz"]] == 0).all(axis=1)]
    assert np.abs(zero.groupby(["repetition", "axis"])[["ux", "uy", "uz"]].mean()).max().max() < 1e-12


@pytest.fixture(scope="module")
def fast_sim_model(tmp_path_factory, sim_dir):
    """`fsdecouple fit` of the session's simulated set at Table 2's tolerance (FAST_CONFIG),
    without its verdict: the model the same data read another way must give, fit for fit
    (three such fits cost less than two at the default tolerance)."""
    path = tmp_path_factory.mktemp("fast_sim") / "model.json"
    invoke(["fit", sim_dir / "calibration", "-o", path, "-c", FAST_CONFIG, "--no-verdict"])
    return path


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_single_csv_with_repetition_column_gives_same_model(tmp_path, sim_dir, fast_sim_model):
    frames = []
    for rep in range(1, 7):
        df = pd.read_csv(sim_dir / "calibration" / f"rep{rep}.csv", dtype=str)
        df.insert(0, "repetition", str(rep))
        frames.append(df)
    single = tmp_path / "all.csv"
    pd.concat(frames).to_csv(single, index=False)
    a, b = tmp_path / "a.json", fast_sim_model
    invoke(["fit", single, "-o", a, "-c", FAST_CONFIG, "--no-verdict"])
    da, db = json.loads(a.read_text()), json.loads(b.read_text())
    assert da["chi"] == db["chi"] and da["omega"] == db["omega"]


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_axis_column_is_optional(tmp_path, sim_dir, fast_sim_model):
    """Without `axis`, sweeps are inferred from consecutive rows: same model."""
    d = tmp_path / "noaxis"
    d.mkdir()
    for f in (sim_dir / "calibration").glob("*.csv"):
        pd.read_csv(f, dtype=str).drop(columns="axis").to_csv(d / f.name, index=False)
    a, b = tmp_path / "a.json", fast_sim_model
    invoke(["fit", d, "-o", a, "-c", FAST_CONFIG, "--no-verdict"])
    assert json.loads(a.read_text())["chi"] == json.loads(b.read_text())["chi"]


@pytest.mark.slow  # over ~0.8 s: the not-slow run stays under a minute
def test_max_gamma_gate(tmp_path):
    # the gate reads the fit's gamma after decoupling, not the held-out verdict; Table 2's
    # tolerance (FAST_CONFIG): the gate, not the solver's digits, is the point
    fast = ["-c", FAST_CONFIG, "--no-verdict"]
    invoke(["fit", SAMPLE / "calibration", "-o", tmp_path / "a.json", "--max-gamma", "0.5", *fast])
    r = invoke(["fit", SAMPLE / "calibration", "-o", tmp_path / "b.json", "--max-gamma", "1e-6",
                *fast], code=1)
    assert "gate failed" in r.stderr


def test_show_and_flags_override(tmp_path):
    m = tmp_path / "m.json"
    invoke(["fit", SAMPLE / "calibration", "-o", m, "--C", "10", "--delta2", "2", "--no-verdict"])
    svr = json.loads(m.read_text())["settings"]["svr"]
    assert svr["C"] == 10 and svr["gamma"] == 0.25
    assert "chi_zy" in invoke(["show", m]).stdout


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_rotation_from_config(tmp_path):
    cfg = tmp_path / "rot.yaml"
    cfg.write_text("rotation: [[0, -1, 0], [1, 0, 0], [0, 0, 1]]\n" + FAST_SVR)
    plain, rotated = tmp_path / "p.json", tmp_path / "r.json"  # the same fit but the rotation
    # (at Table 2's tolerance, FAST_SVR: a third of the CPU, and the rotation is the point)
    invoke(["fit", SAMPLE / "calibration", "-o", plain, "-c", FAST_CONFIG, "--no-verdict"])
    invoke(["fit", SAMPLE / "calibration", "-o", rotated, "-c", cfg, "--no-verdict"])
    from fsdecouple import load_model
    u = np.array([[0.3, -0.2, -0.5]])
    f = load_model(plain).decouple(u)[0]
    np.testing.assert_allclose(load_model(rotated).decouple(u)[0], [-f[1], f[0], f[2]], rtol=1e-12)


def test_zero_option_equals_tare(tmp_path, sim_dir, sim_model_file):
    m = sim_model_file
    log = pd.read_csv(sim_dir / "task_voltages.csv")
    offs = log[["ux", "uy", "uz"]].iloc[:50].mean().to_numpy()
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    invoke(["apply", m, sim_dir / "task_voltages.csv", "-o", a, "--tare", "50"])
    invoke(["apply", m, sim_dir / "task_voltages.csv", "-o", b,
            "--zero", ",".join(repr(float(v)) for v in offs)])
    np.testing.assert_allclose(pd.read_csv(a)[["fx", "fy", "fz"]], pd.read_csv(b)[["fx", "fy", "fz"]],
                               atol=1e-9)


def test_apply_keeps_rows_with_missing_values(tmp_path, sim_model_file):
    m = sim_model_file
    log = tmp_path / "log.csv"
    log.write_text("t,ux,uy,uz\n0,0.1,0.0,-0.1\n1,,0.0,-0.1\n2,0.2,0.1,-0.2\n")
    out = tmp_path / "f.csv"
    r = invoke(["apply", m, log, "-o", out])
    assert "1 row has a missing voltage" in r.stderr and "(row 3)" in r.stderr
    f = pd.read_csv(out)
    assert len(f) == 3 and f["fx"].isna().tolist() == [False, True, False]
    assert f["status"].tolist() == ["ok", "missing", "ok"]


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_apply_chunks_give_same_result(tmp_path, model, sim_dir):
    from fsdecouple.logs.apply import apply_file

    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    apply_file(model, sim_dir / "task_voltages.csv", a, tare=200)
    apply_file(model, sim_dir / "task_voltages.csv", b, tare=200, chunk_rows=7)
    assert a.read_bytes() == b.read_bytes()


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_python_module_entry_point():
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", "fsdecouple", "--help"], capture_output=True, text=True)
    assert r.returncode == 0 and "apply" in r.stdout


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_apply_counts_rows_outside_calibrated_range(tmp_path, model):
    from fsdecouple.logs.apply import apply_file

    lo, hi = model.calibrated_range.T
    span = hi - lo
    rows = [
        (0.5 * (lo[0] + hi[0]), 0.0, -0.5),  # inside
        (hi[0] + 0.005 * span[0], 0.0, -0.5),  # within the 1 % margin: not counted
        (hi[0] + 0.05 * span[0], 0.0, -0.5),  # 5 % beyond: counted
        (0.0, lo[1] - 0.5, -0.5),  # far below on y: counted
    ]
    log = tmp_path / "log.csv"
    log.write_text("ux,uy,uz\n" + "".join(f"{float(a)!r},{float(b)!r},{float(c)!r}\n" for a, b, c in rows))
    summary = apply_file(model, log, tmp_path / "f.csv")
    assert summary.out_of_range_rows == 2 and summary.rows == 4


@pytest.mark.slow  # over ~0.6 s: the not-slow run stays under a minute
def test_outputs_get_the_usual_file_mode(tmp_path):
    """Atomic writes go through mkstemp (mode 0600); the result must not stay private."""
    import os

    old = os.umask(0o022)
    try:
        out = tmp_path / "m.json"
        invoke(["fit", SAMPLE / "calibration", "-o", out, "-c", FAST_CONFIG, "--no-verdict"])
    finally:
        os.umask(old)
    assert out.stat().st_mode & 0o777 == 0o644


# The commands of one _on_a_terminal call, run one after the other by the CLI's app in
# one process (what `python -m fsdecouple` runs, less main()'s signal handling), each
# output headed by a line of its own; an entry {"NAME": "value"} instead of a command
# sets that environment variable for the commands after it (the CLI reads CI when a
# command runs: cli/app.py, interactive())
_TERMINAL_RUNNER = """
import json, os, sys
from fsdecouple.cli.app import app
i = 0
for args in json.loads(sys.argv[1]):
    if isinstance(args, dict):
        os.environ.update(args)
        continue
    print(f"@@ command {i} @@", flush=True)
    i += 1
    try:
        code = app(args, prog_name="fsdecouple", standalone_mode=False)
    except SystemExit as stop:
        code = stop.code
    sys.stdout.flush()
    sys.stderr.flush()
    print(f"@@ exit {code or 0} @@", flush=True)
"""


def _on_a_terminal(commands, env) -> list[str]:
    """Run ``commands`` (lists of CLI arguments, or a dict of environment variables to set
    for the commands after it) in one Python process with a pseudo-terminal as stdout and
    stderr; each command's output.  One interpreter for all: each start-up costs ~1 s of
    CPU, and the terminal, not the process, is the point."""
    import json
    import os
    import pty
    import re
    import subprocess
    import sys

    master, slave = pty.openpty()
    proc = subprocess.Popen([sys.executable, "-c", _TERMINAL_RUNNER,
                             json.dumps([args if isinstance(args, dict) else list(map(str, args))
                                         for args in commands])],
                            stdin=slave, stdout=slave, stderr=slave, env=env)
    os.close(slave)
    chunks = []
    while True:
        try:
            data = os.read(master, 1 << 16)
        except OSError:  # EIO: the child closed the terminal
            break
        if not data:
            break
        chunks.append(data)
    os.close(master)
    text = b"".join(chunks).decode(errors="replace")
    assert proc.wait(timeout=120) == 0, text
    parts = re.split(r"@@ command \d+ @@\r?\n", text)[1:]
    assert len(parts) == len([c for c in commands if not isinstance(c, dict)]), text
    for part in parts:
        assert re.search(r"@@ exit 0 @@\r?\n$", part), part
    return parts


@pytest.mark.slow  # runs the CLI under a pseudo-terminal
def test_progress_bars_show_on_a_terminal_and_never_in_ci(tmp_path, sample_model):
    import os

    env = {k: v for k, v in os.environ.items() if k != "CI"}
    env.update(TERM="xterm-256color", COLUMNS="100")
    cal = SAMPLE / "calibration"
    log = SAMPLE / "task_voltages.csv"
    apply_args = ["apply", sample_model, log, "-o", tmp_path / "f.csv", "--force"]
    # one cv round and a fit without its verdict draw the same bars as the whole runs
    # (at Table 2's tolerance, FAST_CONFIG: the bars, not the solver, are the point)
    cv_args = ["cv", cal, "--folds", "1,2", "-c", FAST_CONFIG, "-o", tmp_path / "cv.json", "--force"]
    fit_args = ["fit", cal, "-c", FAST_CONFIG, "-o", tmp_path / "m.json", "--force", "--no-verdict"]
    hide_cursor = "\x1b[?25l"  # rich hides the cursor while a live bar is drawn
    # the same terminal, then CI=true set (one interpreter: the CLI reads CI per command)
    *outs, out, cv_out = _on_a_terminal([apply_args, cv_args, fit_args, {"CI": "true"},
                                         apply_args, cv_args], env)
    for out_, label in zip(outs, ("decoupling", "training", "fitting"), strict=True):
        assert hide_cursor in out_ and label in out_, out_
        assert "[progress" not in out_ and "tuning" not in out_, out_  # styles, not markup text
    assert "decoupling" not in out and hide_cursor not in out
    assert hide_cursor not in cv_out


@pytest.mark.slow  # a CLI process
def test_no_progress_bar_in_a_redirected_log_whatever_forces_colour(tmp_path, sample_model):
    """FORCE_COLOR=1 or TTY_COMPATIBLE=1 (set by some CI runners) made rich call a
    redirected stderr a terminal: 1.9 kB of the bar's escapes went into the log."""
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "CI"}
    env.update(FORCE_COLOR="1", TTY_COMPATIBLE="1", TERM="xterm-256color")
    r = subprocess.run([sys.executable, "-m", "fsdecouple", "apply", str(sample_model),
                        str(SAMPLE / "task_voltages.csv"), "-o", str(tmp_path / "f.csv")],
                       capture_output=True, text=True, env=env, check=True)
    assert "\x1b[?25l" not in r.stderr and "decoupling" not in r.stderr, r.stderr


def test_a_warning_quoting_a_newline_stays_one_line(capsys):
    """A sensor directory named 'bad<newline>name' split fit-many's warnings and errors."""
    from fsdecouple.cli.app import say, warn

    warn(["sensor bad\nname: gate failed"])
    say(["bad\nname/rep1.csv: not a calibration file"])
    err = capsys.readouterr().err
    assert err.splitlines() == ["warning: sensor bad\\nname: gate failed",
                                "error: bad\\nname/rep1.csv: not a calibration file"]


@pytest.mark.slow  # over ~0.6 s: the not-slow run stays under a minute
def test_usage_errors_are_one_line_and_exit_2(sample_model):
    """A missing argument, a bad option value or an unknown command: bad input like any
    other, through the CLI's main (what `python -m fsdecouple` runs)."""
    import re
    import subprocess
    import sys

    log = SAMPLE / "task_voltages.csv"
    cases = {
        "Missing argument 'voltages'": ["apply", sample_model],
        "Invalid value for '--tare'": ["apply", sample_model, log, "-o", "x.csv", "--tare", "abc"],
        "Did you mean 'apply'?": ["aply"],
        "No such option: --bogus": ["cv", SAMPLE / "calibration", "--bogus"],
    }
    # one process runs the CLI's main once per case (each start-up costs ~1 s of CPU);
    # each case's output on each stream follows a line of its own
    runner = ("import json, sys\n"
              "from fsdecouple.cli import main\n"
              "for i, args in enumerate(json.loads(sys.argv[1])):\n"
              "    print(f'@@ case {i} @@', flush=True)\n"
              "    print(f'@@ case {i} @@', file=sys.stderr, flush=True)\n"
              "    sys.argv = ['fsdecouple', *args]\n"
              "    try:\n"
              "        main()\n"
              "    except SystemExit as stop:\n"
              "        print(f'@@ exit {stop.code} @@', file=sys.stderr, flush=True)\n")
    p = subprocess.run([sys.executable, "-c", runner,
                        json.dumps([list(map(str, args)) for args in cases.values()])],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    outs = re.split(r"@@ case \d+ @@\n", p.stdout)[1:]
    errs = re.split(r"@@ case \d+ @@\n", p.stderr)[1:]
    assert len(outs) == len(errs) == len(cases), (p.stdout, p.stderr)
    for expected, stdout, stderr in zip(cases, outs, errs, strict=True):
        stderr, code = stderr.removesuffix("\n").rsplit("\n", 1)
        lines = stderr.splitlines()
        assert code == "@@ exit 2 @@" and len(lines) == 1, stderr
        assert lines[0].startswith("error: ") and expected in lines[0] and "--help" in lines[0]
        assert "Traceback" not in stderr and stdout == ""


@pytest.mark.slow  # a six-axis cv
def test_redirected_output_keeps_every_column_and_every_sentence_whole(tmp_path):
    """Not on a terminal (a CI log read with grep): the six-axis cv table, 30 gamma
    columns wide, keeps its svr columns, and no sentence is wrapped."""
    import subprocess
    import sys

    six = SAMPLE / "six_axis"
    # one round (--folds 1,2) prints the same 30-column table as three
    r = subprocess.run([sys.executable, "-m", "fsdecouple", "cv", six / "calibration", "-c",
                        six / "sensor.yaml", "--folds", "1,2", "-o", tmp_path / "cv.json"],
                       capture_output=True, text=True, timeout=600, env={**os.environ, "COLUMNS": "80"})
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    at = next(i for i, line in enumerate(lines) if "test (rep)" in line)
    assert lines[at].count("γmz") == 5 and lines[at].split()[-1] == "γmz", lines[at]
    assert lines[at - 1].split()[-1] == "svr", lines[at - 1]  # the methods, initial ... svr
    summary = [line for line in lines if line.startswith("svr ")]  # one sentence, one line
    assert summary and all(line.rstrip().endswith("cells worse than initial") for line in summary)


def test_every_commands_help_reads_as_plain_words():
    """--help of every command: no Python type names (<list[str]>, <bool>), no volts
    assumed for count data, and --version says what it does."""
    import typer.main

    from fsdecouple.cli import app as typer_app

    commands = sorted(typer.main.get_command(typer_app).commands)
    assert {"fit", "apply", "cv", "validate", "export", "fit-many"} <= set(commands)
    for command in [None, *commands]:
        args = ["--help"] if command is None else [command, "--help"]
        text = invoke(args).stdout
        for bad in ("list[", "<bool>", "[V]"):
            assert bad not in text, (command, bad, text)
        if command in ("apply", "validate", "certificate"):  # they take a model: its settings
            assert "the paper's sensor" not in text and "the model's own settings" in text, text
    assert "Print the version" in invoke(["--help"]).stdout
