"""Messages a user can act on (issue 34, unclear messages and smaller problems)."""

from __future__ import annotations

import pytest
from conftest import FAST_CONFIG, FAST_SVR, SAMPLE, assert_one_line_error, invoke


@pytest.fixture(scope="module")
def gauges_model(tmp_path_factory):
    """A rig of eight gauges for six components (M > N), fitted as the docs say."""
    d = tmp_path_factory.mktemp("g8")
    invoke(["simulate", d / "rig", "--rig", "lever-arm", "--gauges", "8"])
    cal = d / "rig" / "calibration.csv"
    invoke(["init", cal, "-o", d / "cfg.yaml"])
    r = invoke(["fit", cal, "-c", d / "cfg.yaml", "-o", d / "m.json", "--no-verdict"])
    return d / "m.json", cal, r


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_fit_of_m_gt_n_suggests_no_report_that_would_refuse_it(gauges_model):
    model, _, r = gauges_model
    invoke(["report", model, "-o", model.parent / "r.html"], 2)  # report refuses M > N
    assert "fsdecouple report" not in r.stdout + r.stderr


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_the_joint_rows_warning_names_its_file_once(gauges_model):
    model, cal, r = gauges_model
    line = next(ln for ln in r.stderr.splitlines() if "several components" in ln)
    assert line.count(str(cal)) == 1, line


def test_interval_on_m_gt_n_says_it_is_not_supported(gauges_model, tmp_path):
    model, cal, _ = gauges_model
    r = invoke(["apply", model, cal, "--interval", "0.9", "-o", tmp_path / "f.csv"], 2)
    msg = assert_one_line_error(r, "not supported", "M > N")
    assert "older fsdecouple" not in msg and "refit" not in msg


def test_the_coverage_is_quoted_as_written(sample_model, tmp_path):
    r = invoke(["apply", sample_model, SAMPLE / "task_voltages.csv", "--tare", "2",
                "--interval", "0.9999999", "-o", tmp_path / "f.csv"], 2)
    assert_one_line_error(r, "--interval: coverage 0.9999999:")


def test_the_top_level_help_says_what_the_tool_is_now():
    text = " ".join(invoke(["--help"]).stdout.split())
    assert "3-axis" not in text and "six eps-SVRs" not in text
    assert "multi-axis force sensors" in text and "eq. (11)" in text


def test_certificate_titles_keep_iso_376_together(sample_model):
    """A title wrapped between 'ISO' and '376' (a no-break space holds them together), and the
    terminal's class table is as wide as its title."""
    r = invoke(["certificate", sample_model, SAMPLE / "calibration"], 0, terminal_width=40)
    assert "ISO\u00a0376" in r.stdout and "ISO\n" not in r.stdout


@pytest.mark.slow  # a levels cv: every method trained once per load level
def test_the_levels_report_speaks_of_load_levels(unrendered, sample_model, tmp_path):
    from fsdecouple.core.modelfile import load_model
    from fsdecouple.evaluation.cv_results import load_cv_results
    from fsdecouple.reporting.report import build_report

    cv = tmp_path / "cv.json"
    # Table 2's tolerance and one repetition (a lab's single calibration) on every other
    # load level: the report's words are the point, and a levels cv trains every method
    # once per load level (of the six repetitions at Table 2's tolerance: ~30 s of CPU; of
    # one, ~4 s; of half its levels, ~2 s)
    (tmp_path / "cal").mkdir()
    lines = (SAMPLE / "calibration" / "rep1.csv").read_text().splitlines()
    kept = [ln for ln in lines[1:] if round(sum(abs(float(v)) for v in ln.split(",")[1:4])) % 20 == 0]
    (tmp_path / "cal" / "rep1.csv").write_text("\n".join([lines[0], *kept]) + "\n")
    (tmp_path / "one.yaml").write_text("min_repetitions: 1\n" + FAST_SVR)
    invoke(["cv", tmp_path / "cal", "--protocol", "levels", "-c", tmp_path / "one.yaml", "-o", cv])
    html = build_report(load_model(sample_model), load_cv_results(cv)).html  # figures not rasterised
    assert "same held-out load level" in html and "same held-out repetition" not in html


def test_a_rig_file_without_a_config_points_to_init(tmp_path):
    invoke(["simulate", tmp_path / "rig", "--rig", "lever-arm"])
    cal = tmp_path / "rig" / "calibration.csv"
    r = invoke(["fit", cal, "-o", tmp_path / "m.json"], 2)
    assert_one_line_error(r, "none of the built-in columns", f"fsdecouple init {cal}")


def test_six_axis_units_are_each_rows_own(tmp_path):
    """Issue 34: 'k [N / N·m/load]', '1/k [load/N / N·m]' and 'outputs peak at 22.892 mixed':
    a wrench's figures carry each component's units in its own row."""
    invoke(["simulate", tmp_path / "rig", "--rig", "lever-arm"])
    cal, cfg = tmp_path / "rig" / "calibration.csv", tmp_path / "cfg.yaml"
    r = invoke(["init", cal, "-o", cfg])
    text = " ".join(r.stdout.split())
    assert " mixed" not in text and "peak at fx_out" in text and "mz_out" in text
    r = invoke(["fit", cal, "-c", cfg, "-o", tmp_path / "m.json", "--no-verdict"])
    assert "/load" not in r.stdout and "load/" not in r.stdout and "N / N·m" not in r.stdout
    rows = {ln.split("│")[1].strip(): ln for ln in r.stdout.splitlines()
            if ln.startswith("│") and "[" in ln.split("│")[1]}
    assert "N/N" in rows["fx [N]"] and "N·m/N·m" in rows["mz [N·m]"], rows
    chi = [ln for ln in r.stdout.splitlines() if ln.startswith("│ chi_")]
    assert all(ln.rstrip(" │").endswith((" N", " N·m")) for ln in chi), chi


def test_fit_of_a_simulate_folder_points_to_its_calibration(tmp_path):
    """`fit OUT` of simulate's output read task_forces.csv as a calibration and suggested
    `init` on it; the calibration is OUT/calibration."""
    out = tmp_path / "B"
    (out / "calibration").mkdir(parents=True)
    for name in ("rep1.csv", "rep2.csv"):
        (out / "calibration" / name).write_bytes((SAMPLE / "calibration" / name).read_bytes())
    (out / "task_forces.csv").write_bytes((SAMPLE / "task_forces.csv").read_bytes())
    r = invoke(["fit", out, "-o", tmp_path / "m.json"], 2)
    assert_one_line_error(r, "task_forces.csv", f"the calibration is in {out / 'calibration'}: "
                          "give that directory")
    assert "fsdecouple init" not in r.stderr and not (tmp_path / "m.json").exists()


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_the_tables_of_an_m_gt_n_fit_say_what_their_numbers_are(gauges_model):
    """v = P u is in the loads' own units: its k is a pure number (it was shown as
    '1 V/N'); a chi of the loads merges the gauges' SVRs, so it has more support vectors
    than points ('442 / 60'), which the table now says."""
    _, _, r = gauges_model
    out = " ".join(r.stdout.split())
    rows = [line for line in r.stdout.splitlines() if line.startswith("│") and "[N" in line][:6]
    assert rows and all(line.split("│")[2].strip() == "1" for line in rows), rows
    assert "merges the 8 gauges' SVRs" in out and "zero offsets:" in out  # caption kept


def test_a_linear_model_says_it_decouples_by_the_matrix(tmp_path):
    """`fit --method linear`: the gamma column was headed 'after (eq. 11)' over the matrix's
    figures, `show` never said the model decouples by the matrix, and fit recommended
    '--tune --refine', which a matrix does not use."""
    r = invoke(["fit", SAMPLE / "calibration", "-o", tmp_path / "m.json", "--method", "linear",
                "--no-verdict", "-c", FAST_CONFIG])
    for out in (r.stdout, invoke(["show", tmp_path / "m.json"]).stdout):
        text = " ".join(out.split())
        assert "after (the matrix f = C u)" in text and "after (eq. 11)" not in text
        assert "the model decouples by the least-squares calibration matrix" in text
    assert "--refine" not in r.stdout and "--tune" not in r.stdout
