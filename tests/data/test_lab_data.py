"""Real lab data (issue "Real lab data"): each finding a new user met, as a test.

The lab sample (sample_data/loadcell, `simulate --layout lab`) has one repetition,
a zero row and four weights per sweep, gram-force loads, ADC counts, two unnamed
columns and a side table that runs past the data.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import ROOT, SAMPLE, invoke

from fsdecouple import load_calibration, load_config
from fsdecouple.core.metrics import interference_error
from fsdecouple.data.calibration import GrossError
from fsdecouple.errors import InputError
from fsdecouple.evaluation.calibrate import fit as calibrate
from fsdecouple.evaluation.heldout import level_rounds
from fsdecouple.evaluation.verdict import heldout_verdict
from fsdecouple.fitting.linear import fit_calibration_matrix
from fsdecouple.fitting.outliers import FLOOR, gross_errors

LAB = SAMPLE / "loadcell" / "calibration.csv"
CONFIG = ROOT / "configs" / "loadcell.yaml"


@pytest.fixture(scope="module")
def lab():
    settings = load_config(CONFIG)
    return load_calibration(LAB, settings), settings


def test_unnamed_columns_and_a_side_table_are_ignored(lab):
    """Finding 1 ('column 10 has no name') and 2 (a repetition column was required)."""
    calib, _ = lab
    assert calib.repetitions == [1]
    # three sweeps of a zero row and four weights; the side table's rows past the
    # data are skipped and listed, not read as points
    assert len(calib.points) == 15
    assert all(calib.points.groupby("axis").size() == 5)
    past = [m for m in calib.skipped if "no value in any mapped column" in m]
    text = LAB.read_text().splitlines()
    data_rows = sum(1 for line in text[1:] if line.split(",")[0].strip())
    assert len(past) == len(text) - 1 - data_rows > 0


def test_a_config_that_maps_a_duplicated_header_is_refused(tmp_path):
    f = tmp_path / "dup.csv"
    f.write_text("fx,fy,fz,ux,uy,uz,ux\n0,0,0,1,2,3,4\n5,0,0,6,2,3,4\n")
    with pytest.raises(InputError, match=r"column 'ux'.*appears 2 times"):
        load_calibration(f, load_config())


def test_counts_are_shown_as_counts_not_volts(tmp_path):
    """Finding 3: k was printed in V/N and zero offsets as millions of mV."""
    r = invoke(["fit", LAB, "-c", CONFIG, "-o", tmp_path / "m.json", "--no-verdict"])
    assert "k [count/gf]" in r.stdout and "input range [count]" in r.stdout
    assert "V/N" not in r.stdout
    r = invoke(["ingest", LAB, "-c", CONFIG])
    assert "Zero offsets removed [count]" in r.stdout and "[mV]" not in r.stdout
    assert "load grid [gf]" in r.stdout


def test_one_repetition_is_validated_by_holding_out_load_levels(lab):
    """Finding 4: cv refused a single repetition; now each round holds out a level."""
    calib, settings = lab
    rounds = level_rounds(calib)
    assert len(rounds) == 4  # four weights per sweep
    for rnd in rounds:
        held = [*(t for _, t in rnd.tests), *([rnd.end] if rnd.end is not None else [])]
        n_held = sum(len(t.points) for t in held)
        assert n_held == 3 and len(rnd.train.points) == 12  # one point of each sweep out
    # the heaviest weight (round 4) is beyond every load left: an end point
    assert rounds[-1].end is not None and not rounds[-1].tests
    assert all(r.end is None for r in rounds[:-1])


def test_verdict_recomputes_the_matrix_figure_independently(lab):
    """Finding 5: the held-out figure of the calibration matrix, re-derived by hand."""
    calib, settings = lab
    v = heldout_verdict(calib, settings)
    assert v["protocol"] == "levels" and v["rounds"] == 4
    worst = 0.0
    for rnd in level_rounds(calib):
        matrix = fit_calibration_matrix(rnd.train.voltages, rnd.train.forces)
        for _, test in rnd.tests:
            f = test.voltages @ matrix.C.T
            axis = test.points["axis"].to_numpy()
            for a, name in enumerate("xyz"):
                if (axis == name).any():
                    worst = max(worst, interference_error(f[axis == name], a, settings.full_scale[a]))
    assert v["heldout"]["linear"]["worst_gamma"] == pytest.approx(worst, rel=1e-12)


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_fit_warns_when_the_matrix_generalizes_better_and_auto_takes_it(tmp_path, lab):
    """Finding 5: on a sensor with linear coupling the matrix is right; fit says so."""
    calib, settings = lab
    pts = calib.points.copy()
    u = pts[["ux", "uy", "uz"]].to_numpy()
    f = pts[["fx", "fy", "fz"]].to_numpy()
    k = np.array([812.5, -1347.5, 415.0])
    coupling = np.array([[0, 0.02, -0.01], [0.015, 0, 0.01], [-0.02, 0.01, 0]])
    rng = np.random.default_rng(3)
    pts[["ux", "uy", "uz"]] = f * k + (f @ coupling.T) * np.abs(k) + rng.normal(0, 5, u.shape)
    linear = type(calib)(pts, calib.offsets, calib.files)
    model = calibrate(linear, settings, method="svr")
    v = model.report.verdict
    assert v["better"] == "linear"
    assert any("calibration matrix generalizes better" in w for w in model.warnings)
    auto = calibrate(linear, settings, method="auto")
    assert auto.method == "linear" and auto.report.verdict["chosen"] == "linear"
    # a linear model decouples by its matrix: f = C u
    np.testing.assert_allclose(auto.decouple(linear.voltages, rotate=False),
                               linear.voltages @ auto.matrix.T, rtol=0, atol=1e-12)


def test_fit_json_carries_the_verdict_and_the_model_the_choice(tmp_path):
    out = tmp_path / "m.json"
    doc = json.loads(invoke(["fit", LAB, "-c", CONFIG, "--method", "auto", "-o", out,
                             "--json"]).stdout)
    v = doc["verdict"]
    assert v["protocol"] == "levels" and v["chosen"] in ("svr", "linear")
    for m in ("initial", "linear", "svr"):
        assert 0 <= v["heldout"][m]["worst_gamma"] < 1
        assert v["heldout"][m]["worst_gamma_end"] is not None
    chosen = v["heldout"][v["chosen"]]["worst_gamma"]
    assert chosen <= v["heldout"]["linear"]["worst_gamma"]
    stored = json.loads(out.read_text())
    assert stored["method"] == v["chosen"] == doc["method"]
    assert stored["report"]["verdict"]["heldout"] == v["heldout"]


def test_a_gross_error_is_flagged_with_file_row_and_size(lab, tmp_path):
    """Finding 6: a point 3.3 % F.S. off passed every check."""
    calib, settings = lab
    k_y = -1347.5  # counts per gf of the lab sample's y channel
    moved = GrossError("y", 1, 3, 0.033 * 1000 * k_y).apply(calib.points)
    found = gross_errors(moved, np.array([812.5, k_y, 415.0]), settings.full_scale)
    assert len(found) == 1
    o = found[0]
    row = int(moved[moved["axis"] == "y"]["row"].iloc[2])
    assert (o.file, o.row, o.output) == (str(LAB), row, "uy")
    assert abs(o.fraction) == pytest.approx(0.033, rel=0.05) and abs(o.fraction) > FLOOR
    assert "gf" in o.message("gf") and "% F.S." in o.message("gf")
    assert gross_errors(calib.points, np.array([812.5, k_y, 415.0]), settings.full_scale) == []


@pytest.mark.slow  # two fits: seconds of CPU; the not-slow run stays under a minute
def test_exclude_drops_a_point_and_the_provenance_records_it(tmp_path):
    out = tmp_path / "m.json"
    invoke(["simulate", tmp_path / "sim", "--gross-error", "x:1:5:0.2"])
    cal = tmp_path / "sim" / "calibration"
    r = invoke(["fit", cal, "-o", out, "--no-verdict"])
    assert "rep1.csv, row 6: possible gross error: ux" in r.stderr
    r = invoke(["fit", cal, "-o", out, "--no-verdict", "--force", "--exclude", "rep1.csv:6"])
    assert "possible gross error" not in r.stderr
    assert json.loads(out.read_text())["provenance"]["excluded"] == [
        f"{cal / 'rep1.csv'}, row 6: excluded as asked"]


def test_help_does_not_offer_a_value_for_flags():
    """Also seen: '--force <bool>' in --help, while '--force true' fails."""
    r = invoke(["fit", "--help"])
    assert "--force" in r.stdout and "<bool>" not in r.stdout


@pytest.mark.slow  # a whole cv run: seconds of CPU; the not-slow run stays under a minute
def test_redirected_cv_output_keeps_every_column():
    """Also seen: rich cut the cv tables at 80 columns in a CI log."""
    r = invoke(["cv", SAMPLE / "calibration", "--folds", "1,2"])
    header = next(line for line in r.stdout.splitlines() if "rbf-mimo" in line)
    for method in ("initial", "linear", "rbf-mimo", "rbf-siso", "svr"):
        assert method in header


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_fit_prints_the_assumption_checks_the_report_shows(tmp_path):
    """Also seen: the report's WARN (slope yx 0.053) that fit never printed."""
    from fsdecouple.core.modelfile import load_model
    from fsdecouple.evaluation.checks import assumption_checks

    out = tmp_path / "m.json"
    r = invoke(["fit", SAMPLE / "calibration", "-o", out, "--no-verdict"])
    assert "Assumption checks" in r.stdout
    warned = [c for c in assumption_checks(load_model(out)) if c.status == "warn"]
    assert warned  # the sample's slope of chi_yx is above 0.05
    for c in warned:
        line = next(x for x in r.stdout.splitlines() if f" {c.name} " in x and f" {c.subject} " in x)
        assert "warning" in line
