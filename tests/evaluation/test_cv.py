"""The cross-validation protocol (cv.py) and the `fsdecouple cv` command."""

from __future__ import annotations

import io
import json
import re

import numpy as np
import pandas as pd
import pytest
from conftest import FAST_CONFIG, FAST_SVR, ROOT, SAMPLE, invoke

from fsdecouple.axes import VOLTAGE_COLUMNS
from fsdecouple.core.metrics import interference_error
from fsdecouple.data.calibration import GrossError
from fsdecouple.errors import InputError
from fsdecouple.evaluation.cv import METHODS, run_cv
from fsdecouple.evaluation.heldout import check_folds, default_folds, parse_folds
from fsdecouple.fitting.linear import fit_omega


@pytest.fixture(scope="module")
def doc(sim_dir, calib, settings):
    return run_cv(
        calib, settings, task=(sim_dir / "task_voltages.csv", sim_dir / "task_forces.csv"),
        task_tare=200, gross_error=GrossError.parse("x:1:5:0.2"), max_gamma=0.016, workers=2,
    )


def _table2_tolerance(settings):
    """``settings`` with Table 2's libsvm tolerance (FAST_SVR's), for checks of what is
    fitted and how, not of the solver's last digits."""
    from dataclasses import replace

    return replace(settings, svr=replace(settings.svr, tolerance=1e-3))


def test_gamma_by_hand():
    forces = np.array([[100.0, 1.0, -2.0], [50.0, -3.0, 0.5], [0.0, 0.0, 0.0]])
    # loaded along x: (max|fy| + max|fz|) / F_FS = (3 + 2) / 100
    assert interference_error(forces, 0, 100.0) == pytest.approx(0.05)
    # loaded along y (fy is then the prime force): (max|fx| + max|fz|) / 150
    assert interference_error(forces, 1, 150.0) == pytest.approx(102.0 / 150.0)


@pytest.mark.slow  # a whole cv run: seconds of CPU; the not-slow run stays under a minute
def test_records_are_gamma_of_the_decoupled_held_out_points(doc, settings):
    """Recompute every gamma record from the decoupled points in the same document."""
    pts = pd.DataFrame(doc["points"])
    for rec in doc["records"]:
        p = pts[(pts["round"] == rec["round"]) & (pts["test_set"] == rec["test_set"])
                & (pts["method"] == rec["method"]) & (pts["axis"] == rec["axis"])]
        a = "xyz".index(rec["axis"])
        f = p[["fx", "fy", "fz"]].to_numpy()
        assert rec["value"] == interference_error(f, a, settings.full_scale[a])


def test_initial_method_is_omega_inverse_of_the_training_data(doc, calib, settings):
    k = fit_omega(calib.subset([3, 4, 5, 6]).points).k
    test = calib.subset([1])
    f = test.voltages / k
    axis = test.points["axis"].to_numpy()
    got = {r["axis"]: r["value"] for r in doc["records"]
           if (r["round"], r["test_set"], r["method"]) == (1, 1, "initial")}
    for a, name in enumerate("xyz"):
        assert got[name] == interference_error(f[axis == name], a, settings.full_scale[a])


def test_one_gamma_record_per_round_test_set_method_axis(doc):
    keys = [(r["round"], r["test_set"], r["method"], r["axis"], r["metric"]) for r in doc["records"]]
    assert len(keys) == len(set(keys)) == 3 * 2 * 5 * 3 == 90
    assert doc["folds"] == [[1, 2], [3, 4], [5, 6]]
    assert {r["method"] for r in doc["records"]} == set(METHODS)
    assert all(0 <= r["value"] < 1 for r in doc["records"])
    assert len(doc["points"]) == 3 * 2 * 73 * 5


def test_methods_behave_as_the_paper_and_the_issue_expect(doc):
    g = pd.DataFrame(doc["records"]).groupby("method")["value"].max()
    # the coupling error model removes most of the 2-5 % F.S. interference
    assert g["initial"] > 0.02 and g["svr"] < 0.016 and g["svr"] < g["linear"]
    task = pd.DataFrame(doc["task"]["records"]).groupby("method")["value"].max()
    # on combined loads the black box, trained on single-axis loads only, is far off
    assert task["svr"] < 0.01 and task["rbf-mimo"] > 10 * task["svr"]
    assert doc["task"]["rows"] == 3000 and doc["task"]["tare"] == 200


def test_gross_error_moves_exactly_one_value(calib):
    ge = GrossError.parse("x:1:5:0.2")
    moved = ge.apply(calib.points)
    before = calib.points[list(VOLTAGE_COLUMNS) + ["fx", "fy", "fz"]].to_numpy()
    after = moved[list(VOLTAGE_COLUMNS) + ["fx", "fy", "fz"]].to_numpy()
    diff = np.argwhere(before != after)
    assert diff.tolist() == [[4, 0]]  # row 5 of repetition 1's x sweep, column ux
    assert after[4, 0] - before[4, 0] == pytest.approx(0.2)


def test_gross_error_only_changes_rounds_that_train_on_it(doc):
    g = doc["gross_error"]
    assert g["rounds_affected"] == [2, 3]  # repetition 1 is held out in round 1
    clean = {(r["round"], r["test_set"], r["method"], r["axis"]): r["value"] for r in doc["records"]}
    gross = {(r["round"], r["test_set"], r["method"], r["axis"]): r["value"] for r in g["records"]}
    assert clean.keys() == gross.keys()
    assert all(gross[k] == clean[k] for k in clean if k[0] == 1)
    omega = {(o["round"], o["axis"]): o for o in g["omega"]}
    assert omega[(2, "x")]["k_gross"] != omega[(2, "x")]["k_clean"]
    assert omega[(2, "y")]["k_gross"] == omega[(2, "y")]["k_clean"]
    assert omega[(1, "x")]["k_gross"] == omega[(1, "x")]["k_clean"]


def test_folds_parsing_and_checks():
    assert parse_folds("1,2;3,4;5,6") == [[1, 2], [3, 4], [5, 6]]
    assert parse_folds(" 1, 2 ;3") == [[1, 2], [3]]  # uneven rounds are allowed
    with pytest.raises(InputError, match="expected repetition numbers"):
        parse_folds("1,a;3,4")
    with pytest.raises(InputError, match="expected repetition numbers"):
        parse_folds("1,2;")
    reps = [1, 2, 3, 4, 5, 6]
    with pytest.raises(InputError, match="round 2 holds out repetition 9"):
        check_folds([[1, 2], [3, 9]], reps)
    with pytest.raises(InputError, match="names a repetition twice"):
        check_folds([[1, 1]], reps)
    with pytest.raises(InputError, match="none is left to train"):
        check_folds([[1, 2, 3]], [1, 2, 3])
    with pytest.raises(InputError, match="at least 3 repetitions"):
        check_folds([[1]], [1, 2])
    assert default_folds(reps) == [[1, 2], [3, 4], [5, 6]]
    assert default_folds([1, 2, 3]) == [[1, 2], [1, 3], [2, 3]]
    assert default_folds([1, 2, 3, 4]) == [[1, 2], [3, 4], [2, 3]]


@pytest.mark.slow  # over ~0.6 s: the not-slow run stays under a minute
def test_parallel_training_equals_sequential(doc, calib, settings):
    seq = run_cv(calib, settings, workers=1)
    assert seq["records"] == doc["records"] and seq["points"] == doc["points"]
    assert doc["timing"]["parallel"]["workers"] == 2


@pytest.mark.slow  # every cv model twice: seconds of CPU; the not-slow run stays under a minute
def test_parallel_models_decouple_bit_for_bit_like_sequential_ones(calib, settings):
    """Every method trained on threads gives the same forces, to the last bit, as alone
    (at Table 2's tolerance: the threads are the point, not the solver's last digits)."""
    from fsdecouple.fitting.baselines import train_all

    jobs = [((r, m), m, calib.subset(train)) for r, train in enumerate([[1, 2, 3, 4], [3, 4, 5, 6]])
            for m in METHODS]
    settings = _table2_tolerance(settings)
    parallel, _ = train_all(jobs, settings, 2, None)
    sequential, _ = train_all(jobs, settings, 1, None)
    u = calib.voltages
    for key in parallel:
        assert np.array_equal(parallel[key].decouple(u), sequential[key].decouple(u)), key


def test_gate_and_timing_and_checks_in_document(doc):
    worst = max(r["value"] for r in doc["records"] if r["method"] == "svr")
    assert doc["gate"] == {"max_gamma": 0.016, "worst": worst, "passed": True}
    t = {(r["method"], r["metric"]) for r in doc["timing"]["records"]}
    assert t == {(m, x) for m in METHODS for x in ("establish_seconds", "decouple_seconds_per_vector")}
    assert {c["round"] for c in doc["checks"]} == {1, 2, 3}
    assert {c["name"] for c in doc["checks"]} == {"linearity", "coupling", "slope", "second_order"}
    assert set(doc["curves"]["chi"]) == {"xy", "xz", "yx", "yz", "zx", "zy"}
    assert len(doc["curves"]["chi"]["xy"]["u"]) == 201


def _documented_layout():
    """The cv.json layout block of docs/cv.md, between its markers."""
    text = (ROOT / "docs" / "cv.md").read_text(encoding="utf-8")
    m = re.search(r"<!-- cv-json-layout -->\n```json\n(.*?)```", text, re.S)
    assert m, "docs/cv.md lacks the cv.json layout block"
    return m.group(1)


def test_cv_json_has_the_documented_keys(doc):
    layout = _documented_layout()
    top = set(re.findall(r'^  "(\w+)":', layout, re.M))
    assert {"format", "records", "task", "gross_error", "timing", "checks", "gate"} <= top
    missing = top - set(doc)
    assert not missing, f"documented but not written: {missing}"
    rec = {"round", "test_set", "method", "axis", "metric", "value"}
    assert all(set(r) == rec for r in doc["records"])
    assert all(set(r) == rec for r in doc["gross_error"]["records"])
    assert all(set(r) == rec - {"test_set"} for r in doc["task"]["records"])
    for key in ("voltages", "forces", "rows", "tare", "records"):
        assert key in doc["task"] and f'"{key}"' in layout
    for key in ("spec", "records", "omega"):
        assert key in doc["gross_error"] and f'"{key}"' in layout
    for key in ("k_clean", "k_gross", "inverse_clean", "inverse_gross"):
        assert all(key in o for o in doc["gross_error"]["omega"]) and f'"{key}"' in layout
    for key in ("workers", "wall_seconds", "sequential_seconds", "speedup"):
        assert key in doc["timing"]["parallel"] and f'"{key}"' in layout
    for key in ("round", "train", "test", "chi"):
        assert key in doc["curves"]
    assert set(doc["checks"][0]) == {"name", "subject", "value", "limit", "status", "round"}
    assert set(doc["points"][0]) == {"round", "test_set", "method", "axis", "load", "fx", "fy", "fz"}
    assert set(doc["rbf"]) >= {"spread", "b", "mse_goal", "output_layer"}
    json.dumps(doc, allow_nan=False)


# --- the command ------------------------------------------------------------------


@pytest.mark.slow  # over ~0.8 s: the not-slow run stays under a minute
def test_cv_command_json_output_and_gate(tmp_path):
    out = tmp_path / "cv.json"
    r = invoke(["cv", SAMPLE / "calibration", "-c", FAST_CONFIG, "--json", "-o", out,
                "--max-gamma", "0.5"])
    doc = json.loads(r.stdout)  # stdout is the document and nothing else
    assert doc == json.loads(out.read_text())
    assert doc["format"] == "fsdecouple.cv" and doc["gate"]["passed"] is True
    r = invoke(["cv", SAMPLE / "calibration", "-o", out], code=2)
    assert "already exists" in r.stderr
    # the failing gate on one round (--folds 1,2): any round's gamma is above 1e-6
    r = invoke(["cv", SAMPLE / "calibration", "-c", FAST_CONFIG, "--max-gamma", "1e-6",
                "--folds", "1,2"], code=1)
    assert "Interference error" in r.stdout and "FAILED" in r.stdout


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--folds", "1,2;3,9"], "round 2 holds out repetition 9"),
        (["--folds", "1,x"], "expected repetition numbers"),
        (["--task", "sample_data/task_voltages.csv"], "--task and --task-forces go together"),
        (["--gross-error", "x:9:5:0.2"], "repetition 9 is not in the calibration set"),
        (["--gross-error", "x:1:99:0.2"], "no point 99"),
        (["--max-gamma", "-1"], "--max-gamma"),
    ],
)
def test_cv_command_bad_input_exits_2(args, message):
    r = invoke(["cv", SAMPLE / "calibration", *args], code=2)
    assert message in r.stderr and "Traceback" not in r.stderr


@pytest.mark.slow  # cv with 30 load-level rounds
def test_fewer_than_three_repetitions_hold_out_load_levels(tmp_path):
    d = tmp_path / "two"
    d.mkdir()
    for rep in (1, 2):
        (d / f"rep{rep}.csv").write_bytes((SAMPLE / "calibration" / f"rep{rep}.csv").read_bytes())
    cfg = tmp_path / "two.yaml"
    cfg.write_text("min_repetitions: 2\n" + FAST_SVR)  # the rounds' layout is the point
    r = invoke(["cv", d, "-c", cfg, "--protocol", "repetitions"], code=2)
    assert "needs at least 3" in r.stderr and "--protocol levels" in r.stderr
    r = invoke(["cv", d, "-c", cfg, "--folds", "1,2"], code=2)  # folds are repetitions
    assert "needs at least 3 repetitions" in r.stderr
    doc = json.loads(invoke(["cv", d, "-c", cfg, "--json"]).stdout)
    assert doc["protocol"] == "levels"
    # the paper's Z sweep has 30 loaded points (0..-150 N in 5 N steps): 30 rounds.
    # X runs -100..100 N in 10 N steps, 20 loaded points in file order; held out,
    # -100 N (round 1) and +100 N (round 20) lie beyond every load left: end points
    assert len(doc["folds"]) == 30
    ends = {(r["round"], r["axis"]) for r in doc["end_records"] if r["method"] == "svr"}
    assert (1, "x") in ends and (20, "x") in ends and (10, "x") not in ends
    interior = {(r["round"], r["axis"]) for r in doc["records"] if r["method"] == "svr"}
    assert (10, "x") in interior and not interior & {(1, "x"), (20, "x")}
    r = invoke(["cv", d], code=2)  # the default config already wants six
    assert "requires at least 6" in r.stderr


def test_cells_worse_than_initial_are_marked(doc):
    from rich.console import Console

    from fsdecouple.reporting.console import gamma_table, summary_lines, task_table

    bad = json.loads(json.dumps(doc))
    for r in bad["records"]:
        if (r["round"], r["test_set"], r["method"], r["axis"]) == (2, 3, "rbf-mimo", "y"):
            r["value"] = 0.5
    console = Console(record=True, width=200, file=io.StringIO())
    console.print(gamma_table(bad))
    text = console.export_text()
    assert "50.00!" in text and text.count("!") == 2  # the cell and the title
    assert "rbf-mimo  worst gamma  50.00 % F.S., 1 of 18 cells worse than initial" in summary_lines(bad)
    console.print(task_table(doc))
    # on combined loads the black box's errors explode: marked beside the numbers
    assert re.search(r"rbf-mimo .*\d!", console.export_text())


@pytest.mark.parametrize("repeats", [1, 2])
@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_table_4_times_the_training_run_s_own_fits(calib, settings, monkeypatch, repeats):
    """cv fitted round 1's models a second time only to time them (Table 4): now the
    first timing pass is those models' own fit in the training run, so each job is fitted
    once, and every further repeat fits round 1's models once more; every method still
    gets a positive establish time."""
    import fsdecouple.evaluation.cv as cv_module
    from fsdecouple.fitting import baselines

    fitted, establish = [], baselines.establish

    def counting(method, train, *args, **kw):
        fitted.append(method)
        return establish(method, train, *args, **kw)

    monkeypatch.setattr(baselines, "establish", counting)
    monkeypatch.setattr(cv_module, "establish", counting)
    # Table 2's tolerance: what is counted is the fits, not their last digits
    doc = run_cv(calib, _table2_tolerance(settings), repeats=repeats, workers=2)
    rounds = len(doc["train"])
    assert sorted(fitted) == sorted(list(METHODS) * (rounds + repeats - 1))
    times = {r["method"]: r["value"] for r in doc["timing"]["records"]
             if r["metric"] == "establish_seconds"}
    assert set(times) == set(METHODS) and all(t > 0 for t in times.values())


@pytest.mark.slow  # a whole cv run
def test_a_config_method_is_named_as_not_used_by_cv(tmp_path):
    """method: is fit's choice; cv scores every method, and says the key was not used
    instead of dropping it in silence."""
    cfg = tmp_path / "m.yaml"
    cfg.write_text("svr: {tolerance: 0.001}\nmethod: linear\n")
    # one round (--folds 1,2): the warning is the document's, whatever the rounds
    r = invoke(["cv", SAMPLE / "calibration", "-c", cfg, "-o", tmp_path / "cv.json", "--json",
                "--folds", "1,2"])
    doc = json.loads((tmp_path / "cv.json").read_text())
    assert doc["folds"] == [[1, 2]]
    assert any("config method: linear not used" in w for w in doc["warnings"]), doc["warnings"]
    assert "config method: linear not used" in r.stdout + r.stderr


def _svr_gamma_by_axis(records) -> dict[str, float]:
    """The worst svr gamma per loaded axis over rounds and held-out sets."""
    out: dict[str, float] = {}
    for r in records:
        if r["method"] == "svr" and r["metric"] == "gamma":
            out[r["axis"]] = max(out.get(r["axis"], 0.0), r["value"])
    return out


def _agree(cv_doc, verdict) -> None:
    got, want = _svr_gamma_by_axis(cv_doc["records"]), verdict["heldout"]["svr"]["gamma"]
    assert got.keys() == want.keys()
    for axis in got:  # cv decouples by the fast-path tables, the verdict by kernel sums
        assert got[axis] == pytest.approx(want[axis], rel=1e-6, abs=1e-12), axis


@pytest.mark.slow  # a whole fit or cv: over half a second of CPU
def test_cv_scores_the_svr_as_the_held_out_verdict_does(doc, calib, settings):
    """cv's rounds are the verdict's protocol, solved alike (fitting/noise.py): the verdict
    (fit's own held-out rounds, another code path) gives cv's svr gamma per axis."""
    from fsdecouple.evaluation.verdict import heldout_verdict

    _agree(doc, heldout_verdict(calib, settings, workers=2))


@pytest.mark.slow  # a cv and a verdict more: seconds of CPU
def test_a_stated_tolerance_is_obeyed_by_cv_as_by_the_verdict(doc, calib, settings):
    from dataclasses import replace

    from fsdecouple.evaluation.verdict import heldout_verdict

    stated = replace(settings, svr=replace(settings.svr, tolerance=1e-3))  # Table 2's
    got = run_cv(calib, stated, workers=2)
    _agree(got, heldout_verdict(calib, stated, workers=2))
    # and the rule's tolerance (doc's) is not the stated one: the figures differ
    assert _svr_gamma_by_axis(got["records"]) != _svr_gamma_by_axis(doc["records"])


def test_the_gamma_table_keeps_the_sensors_axis_order():
    """Under the levels protocol the first round may hold out only the sweep with the most
    levels (z): its column came first (gamma_z, gamma_x, gamma_y)."""
    from fsdecouple.reporting.console import gamma_table

    records = [{"axis": a, "method": "svr", "metric": "gamma", "round": r, "test_set": r,
                "value": 0.001} for r, axes in ((1, "z"), (2, "zxy")) for a in axes]
    doc = {"records": records, "methods": ["svr"], "protocol": "levels", "folds": [[], []],
           "settings": {"full_scale": {"x": 100.0, "y": 100.0, "z": 150.0}}}
    heads = [c.header.split("\n")[-1] for c in gamma_table(doc).columns[2:]]
    assert heads == ["γx", "γy", "γz"]
    # the report's tables take the same order (evaluation.cv_results.scored_axes)
    from fsdecouple.evaluation.cv_results import scored_axes

    assert scored_axes(doc) == ["x", "y", "z"]


@pytest.mark.slow  # two cv runs of one round
def test_cv_refine_adds_a_refined_row_equal_to_a_config_that_refines(calib, settings):
    """Issue 12: cv supports refinement as an extra method row when asked (it had no
    --refine; only a config's refine made the svr row itself refined)."""
    from dataclasses import replace

    fast = _table2_tolerance(settings)
    asked = run_cv(calib, fast, folds=[[1, 2]], refine=2, gross_error=GrossError.parse("x:3:5:0.2"))
    config = run_cv(calib, replace(fast, refine=2), folds=[[1, 2]],
                    gross_error=GrossError.parse("x:3:5:0.2"))
    assert asked["methods"] == [*METHODS, "svr-refined"] and asked["refine"] == 2
    assert config["methods"] == list(METHODS) and config["refine"] is None

    def values(doc, method, key="records"):
        recs = doc[key] if key == "records" else doc[key]["records"]
        return {(r["round"], r["test_set"], r["axis"]): r["value"] for r in recs
                if r["method"] == method}

    for key in ("records", "gross_error"):
        # the refined row is the config-refined svr row: the same models, K = 2
        assert values(asked, "svr-refined", key) == values(config, "svr", key)
        assert values(asked, "svr", key) != values(asked, "svr-refined", key)
    for m in METHODS[:-1]:  # the baselines do not change
        assert values(asked, m) == values(config, m)
    with pytest.raises(InputError, match="refine 0: a refined row needs K >= 1"):
        run_cv(calib, fast, folds=[[1, 2]], refine=0)
