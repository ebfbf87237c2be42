"""`fsdecouple validate`: a model scored on an independent set with known truth.

The validation set comes from the simulator (the sensor of the sample data, a new
seed), with some loads pushed 20 % past the calibrated range.  Every figure is
re-derived here another way: the zero correction by hand, the range split by
`apply`'s own per-row status, the forces by the exact kernel sum.
"""

from __future__ import annotations

import json
import re
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from conftest import ROOT, SAMPLE, assert_one_line_error, invoke

from fsdecouple.axes import AXES, FORCE_COLUMNS, VOLTAGE_COLUMNS
from fsdecouple.core.modelfile import load_model
from fsdecouple.data.calibration import load_calibration
from fsdecouple.errors import InputError
from fsdecouple.evaluation.validate import validate
from fsdecouple.logs.apply import apply_file
from fsdecouple.sim.simulate import SimulatedSensor, simulate_calibration

FS = np.array(SimulatedSensor().full_scale)
TOP_KEYS = {"format", "format_version", "fsdecouple_version", "model", "model_digest", "set",
            "units", "records", "initial", "gate", "warnings"}


def validation_table(seed: int = 11, repetitions: int = 1) -> pd.DataFrame:
    """A simulated single-axis set; loads of 90 N and more are moved to 1.2x (108, 120 N...)."""
    sensor = SimulatedSensor()
    t = simulate_calibration(sensor, repetitions=repetitions, seed=seed)
    f = t[list(FORCE_COLUMNS)].to_numpy()
    f2 = np.where(np.abs(f).max(axis=1, keepdims=True) >= 90.0, 1.2 * f, f)
    # same zero offset and noise, the voltages of the larger load (eq. 1-3)
    t[list(VOLTAGE_COLUMNS)] += sensor.voltages(f2) - sensor.voltages(f)
    t[list(FORCE_COLUMNS)] = f2
    return t


@pytest.fixture(scope="module")
def model_file(sample_model):
    return sample_model  # conftest's model fitted on the sample data


@pytest.fixture(scope="module")
def set_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("validate") / "val.csv"
    validation_table().to_csv(path, index=False)
    return path


@pytest.fixture(scope="module")
def truth(set_file, model_file, tmp_path_factory):
    """Zero-corrected voltages, loads, and apply's verdict on each point, derived by hand."""
    t = pd.read_csv(set_file)
    zero = (t[list(FORCE_COLUMNS)] == 0).all(axis=1)
    u = t[list(VOLTAGE_COLUMNS)].to_numpy().copy()
    for _, idx in t.groupby(["repetition", "axis"]).indices.items():
        u[idx] -= u[idx[zero.to_numpy()[idx]]].mean(axis=0)
    log = tmp_path_factory.mktemp("validate") / "log.csv"
    pd.DataFrame(u, columns=list(VOLTAGE_COLUMNS)).to_csv(log, index=False)
    out = log.with_name("forces.csv")
    apply_file(load_model(model_file), log, out)
    status = pd.read_csv(out)["status"].to_numpy()
    return {"axis": t["axis"].to_numpy(), "u": u, "loads": t[list(FORCE_COLUMNS)].to_numpy(),
            "calibrated": status == "ok"}


@pytest.fixture(scope="module")
def doc(model_file, set_file):
    return validate(model_file, set_file)


def rec(doc, method, axis, metric, rng):
    found = [r for r in doc["records"] if (r["method"], r["axis"], r["metric"], r["range"])
             == (method, axis, metric, rng)]
    assert len(found) <= 1
    return found[0] if found else None


def test_layout(doc, model_file, set_file):
    assert set(doc) == TOP_KEYS
    assert doc["format"] == "fsdecouple.validation" and doc["format_version"] == 1
    assert doc["model"] == str(model_file)
    assert doc["model_digest"] == json.loads(model_file.read_text())["integrity"]["digest"]
    assert doc["set"]["path"] == str(set_file)
    assert doc["set"]["points"] == len(pd.read_csv(set_file))
    assert [set(f) for f in doc["set"]["files"]] == [{"path", "sha256"}]
    assert doc["units"] == {"load": "N", "output": "V"}
    assert doc["gate"] is None
    for r in doc["records"]:
        keys = {"method", "axis", "metric", "range", "value", "n"}
        assert set(r) == (keys if r["metric"] == "gamma" else keys | {"value_load_unit"})
        assert r["method"] in ("model", "linear", "initial")
        assert r["range"] in ("calibrated", "extrapolated")
    # one record per (method, axis, metric, range), both ranges present here
    assert len(doc["records"]) == 3 * 3 * 3 * 2
    json.dumps(doc, allow_nan=False)
    readme = (SAMPLE.parent / "docs" / "validate.md").read_text(encoding="utf-8")
    layout = re.search(r"<!-- validation-json-layout -->\n```json\n(.*?)```", readme, re.S).group(1)
    assert set(re.findall(r'^  "(\w+)":', layout, re.M)) == TOP_KEYS


def test_gamma_rederived_and_initial_is_worse(doc, truth, model_file):
    model = load_model(model_file)
    f_exact = model.decouple(truth["u"], rotate=False, exact=True)
    for a, axis in enumerate(AXES):
        sel = (truth["axis"] == axis) & truth["calibrated"]
        f = f_exact[sel]
        # eq. (12) by hand: the two unloaded components' largest |f|, over FS of the loaded axis
        gamma = sum(np.abs(f[:, b]).max() for b in range(3) if b != a) / FS[a]
        # the table path is within 1e-9 V of the exact kernel sum: ~1e-7 N, far below 1e-6 relative
        assert rec(doc, "model", axis, "gamma", "calibrated")["value"] == pytest.approx(gamma, rel=1e-6)
        initial = rec(doc, "initial", axis, "gamma", "calibrated")["value"]
        assert initial == pytest.approx(
            sum(np.abs(truth["u"][sel, b] / model.k[b]).max() for b in range(3) if b != a) / FS[a])
        # the simulated coupling is 1-3 % F.S.; the model removes most of it
        assert initial > 3 * rec(doc, "model", axis, "gamma", "calibrated")["value"]


def test_errors_against_known_loads(doc, truth, model_file):
    model = load_model(model_file)
    f = model.decouple(truth["u"], rotate=False, exact=True)
    for axis in AXES:
        for rng, sel in (("calibrated", truth["calibrated"]), ("extrapolated", ~truth["calibrated"])):
            sel = sel & (truth["axis"] == axis)
            e = np.abs(f[sel] - truth["loads"][sel]) / FS  # every component, own full scale
            r_max = rec(doc, "model", axis, "max_error", rng)
            r_rms = rec(doc, "model", axis, "rms_error", rng)
            assert r_max["value"] == pytest.approx(e.max(), rel=1e-6)
            assert r_rms["value"] == pytest.approx(np.sqrt((e ** 2).mean()), rel=1e-6)
            assert r_max["value_load_unit"] == pytest.approx(r_max["value"] * FS.max())
            # 0.5 mV noise is ~0.04 N; the fitted model stays within 0.5 % F.S. of the truth
            assert r_max["value"] < 0.005


def test_extrapolated_points_reported_apart(doc, truth):
    for axis in AXES:
        outside = int(((truth["axis"] == axis) & ~truth["calibrated"]).sum())
        # every axis has loads pushed to 1.2x its calibrated extremes
        assert outside >= 2
        assert f"{outside} of {int((truth['axis'] == axis).sum())} {axis}-sweep points" in \
            " ".join(doc["warnings"])
        assert rec(doc, "model", axis, "gamma", "extrapolated") is not None


def test_every_figure_carries_the_number_of_points_behind_it(doc, truth):
    for axis in AXES:
        for rng, sel in (("calibrated", truth["calibrated"]), ("extrapolated", ~truth["calibrated"])):
            n = int((sel & (truth["axis"] == axis)).sum())
            for method in ("model", "linear", "initial"):
                for metric in ("gamma", "max_error", "rms_error"):
                    assert rec(doc, method, axis, metric, rng)["n"] == n  # single loads only here


def lstsq_matrix(calibration: pd.DataFrame) -> np.ndarray:
    """C of f = C u by least squares over the zero-corrected points, derived by hand."""
    t = calibration
    zero = (t[list(FORCE_COLUMNS)] == 0).all(axis=1).to_numpy()
    u = t[list(VOLTAGE_COLUMNS)].to_numpy().copy()
    for _, idx in t.groupby(["repetition", "axis"]).indices.items():
        u[idx] -= u[idx[zero[idx]]].mean(axis=0)
    ct, *_ = np.linalg.lstsq(u, t[list(FORCE_COLUMNS)].to_numpy(), rcond=None)
    return ct.T


def test_linear_is_the_least_squares_matrix_of_the_same_calibration(doc, truth, model_file):
    cal = pd.concat([pd.read_csv(f).assign(repetition=i)
                     for i, f in enumerate(sorted((SAMPLE / "calibration").glob("*.csv")))])
    C = lstsq_matrix(cal)
    stored = np.array(json.loads(model_file.read_text())["matrix"])
    assert stored == pytest.approx(C, rel=1e-9, abs=1e-9 * np.abs(C).max())
    f = truth["u"] @ C.T
    for a, axis in enumerate(AXES):
        sel = (truth["axis"] == axis) & truth["calibrated"]
        gamma = sum(np.abs(f[sel, b]).max() for b in range(3) if b != a) / FS[a]
        assert rec(doc, "linear", axis, "gamma", "calibrated")["value"] == pytest.approx(gamma, rel=1e-9)
        e = np.abs(f[sel] - truth["loads"][sel]) / FS
        assert rec(doc, "linear", axis, "max_error", "calibrated")["value"] == pytest.approx(e.max())
        # the simulated coupling is nonlinear: the matrix leaves more of it than eq. (11)
        assert rec(doc, "linear", axis, "gamma", "calibrated")["value"] > \
            rec(doc, "model", axis, "gamma", "calibrated")["value"]


def test_a_model_file_without_a_matrix_takes_it_from_calib(doc, set_file, model_file):
    old = ROOT / "tests" / "fixtures" / "golden" / "model-v3.json"
    assert "matrix" not in json.loads(old.read_text())
    without = validate(old, set_file)
    assert {r["method"] for r in without["records"]} == {"model", "initial"}
    assert any("give its calibration set" in w for w in without["warnings"])
    given = validate(old, set_file, calib=SAMPLE / "calibration")
    linear = [r for r in given["records"] if r["method"] == "linear"]
    assert linear and not any("give its calibration set" in w for w in given["warnings"])
    # the golden file was fitted on the sample calibration, as model_file was
    assert linear == [r for r in doc["records"] if r["method"] == "linear"]


def test_calib_beside_a_model_that_holds_its_matrix_is_not_ignored_in_silence(set_file, model_file):
    """--calib is read only for a model file without a matrix; beside one that holds it,
    it was ignored without a word (even /dev/zero)."""
    doc = validate(model_file, set_file, calib="/dev/zero")
    assert any("calibration /dev/zero: not read" in w for w in doc["warnings"]), doc["warnings"]


def test_a_range_without_a_loaded_point_has_no_figure(model_file, tmp_path):
    """Every loaded y point pushed past the range: the calibrated y group is its zero rows,
    which scored a perfect 0.0 before; now no figure, and n = 0."""
    t = validation_table()
    y = t["axis"] == "y"
    sensor = SimulatedSensor()
    before = t.loc[y, list(FORCE_COLUMNS)].to_numpy()
    t.loc[y, "fy"] += np.sign(t.loc[y, "fy"]) * 1.1 * FS[1]  # every loaded point past full scale
    f = t.loc[y, list(FORCE_COLUMNS)].to_numpy()
    t.loc[y, list(VOLTAGE_COLUMNS)] += sensor.voltages(f) - sensor.voltages(before)
    path = tmp_path / "far.csv"
    t.to_csv(path, index=False)
    doc = validate(model_file, path, max_gamma=0.5)
    for method in ("model", "linear", "initial"):
        for metric in ("gamma", "max_error", "rms_error"):
            r = rec(doc, method, "y", metric, "calibrated")
            assert r["value"] is None and r["n"] == 0, r
            assert rec(doc, method, "y", metric, "extrapolated")["value"] > 0
    assert doc["gate"]["worst"] == max(r["value"] for r in doc["records"] if r["value"] is not None
                                       and (r["method"], r["metric"], r["range"])
                                       == ("model", "gamma", "calibrated"))
    json.dumps(doc, allow_nan=False)
    r = invoke(["validate", model_file, path])
    cells = [[c.strip() for c in ln.split("│")[1:-1]] for ln in r.stdout.splitlines() if "│" in ln]
    y_rows = [c for c in cells if c[0] == "y"]
    assert len(y_rows) == 6  # three methods, two ranges
    assert [c[2:] for c in y_rows[:3]] == [["0", "-", "-", "-", "-", "-"]] * 3


def test_empty_range_is_absent(model_file, tmp_path):
    t = validation_table()
    t = t[(t[list(FORCE_COLUMNS)].abs() < 50).all(axis=1) | (t["axis"] != "y")]
    path = tmp_path / "small.csv"
    t.to_csv(path, index=False)
    doc = validate(load_model(model_file), path)
    assert doc["model"] is None
    # y loads of at most 40 N stay well inside the calibrated range
    assert rec(doc, "model", "y", "gamma", "extrapolated") is None
    assert rec(doc, "model", "y", "gamma", "calibrated") is not None


def test_other_load_grid_and_one_repetition_accepted(model_file, tmp_path):
    t = validation_table(repetitions=2)
    t = t.drop(index=t.index[(t["repetition"] == 2) & (t["fx"] == 40.0)])
    path = tmp_path / "two.csv"
    t.to_csv(path, index=False)
    # the reader warns, as it should for a calibration; for validation that is noise
    settings = replace(load_model(model_file).settings, min_repetitions=1)
    assert any("load grid" in w for w in load_calibration(path, settings).warnings)
    doc = validate(model_file, path)
    assert not any("load grid" in w for w in doc["warnings"])


def test_cli_gate_and_output(model_file, set_file, tmp_path, doc):
    out = tmp_path / "validation.json"
    r = invoke(["validate", model_file, set_file, "-o", out, "--max-gamma", "0.016"])
    assert "calibrated points" in r.stdout and "extrapolated points" in r.stdout
    written = json.loads(out.read_text())
    assert written["gate"] == {"max_gamma": 0.016, "worst": pytest.approx(max(
        r["value"] for r in doc["records"]
        if (r["method"], r["metric"], r["range"]) == ("model", "gamma", "calibrated"))),
        "passed": True}
    before = out.read_bytes()
    r = invoke(["validate", model_file, set_file, "-o", out], code=2)
    assert "already exists" in r.stderr and out.read_bytes() == before
    r = invoke(["validate", model_file, set_file, "-o", out, "--force", "--json",
                "--max-gamma", "0.001"], code=1)
    assert json.loads(r.stdout) == json.loads(out.read_text())
    assert json.loads(r.stdout)["gate"]["passed"] is False
    assert "FAILED" in r.stderr


@pytest.mark.parametrize("g", ["0", "-0.01", "nan", "inf"])
def test_cli_bad_max_gamma(model_file, set_file, tmp_path, g):
    out = tmp_path / "v.json"
    r = invoke(["validate", model_file, set_file, "--max-gamma", g, "-o", out], code=2)
    assert "--max-gamma" in r.stderr and not out.exists()


def test_cli_refuses_bad_input_and_writes_nothing(model_file, set_file, tmp_path):
    t = validation_table()
    i = t.index[t["fx"] == 50.0][0]
    t.loc[i, "fy"] = 10.0
    bad = tmp_path / "two_at_once.csv"
    t.to_csv(bad, index=False)
    out = tmp_path / "v.json"
    # a combined load is accepted (issue 14), scored by its force errors and named
    r = invoke(["validate", model_file, bad, "-o", out])
    assert "1 combined-load points" in r.stderr and out.exists()
    out.unlink()
    r = invoke(["validate", model_file, tmp_path / "missing.csv", "-o", out], code=2)
    assert "not found" in r.stderr and not out.exists()
    r = invoke(["validate", tmp_path / "missing.json", set_file, "-o", out], code=2)
    assert "not found" in r.stderr and not out.exists()
    # the output may not replace an input, even with --force
    before = set_file.read_bytes()
    r = invoke(["validate", model_file, set_file, "-o", set_file, "--force"], code=2)
    assert "is also an input" in r.stderr and set_file.read_bytes() == before
    with pytest.raises(InputError, match="gate on gamma nan") as err:
        validate(model_file, set_file, max_gamma=float("nan"))
    assert err.value.argument == "max_gamma"  # the CLI names it --max-gamma


def test_cli_prints_file_text_literally(model_file, tmp_path):
    path = tmp_path / "val[red]x[bold].csv"
    validation_table().to_csv(path, index=False)
    r = invoke(["validate", model_file, path])
    assert "val[red]x[bold].csv" in r.stdout.replace("\n", "")


def test_a_set_read_in_other_units_than_the_models_is_refused(sample_model, tmp_path):
    """An N/V model scored on a gf/count set exited 0 with figures in nobody's units."""
    r = invoke(["validate", sample_model, SAMPLE / "loadcell" / "validation.csv", "-c",
                ROOT / "configs" / "loadcell.yaml", "-o", tmp_path / "v.json"], code=2)
    assert_one_line_error(r, "gf", "count", "N", "V", "calibration's config")
    assert not (tmp_path / "v.json").exists()
