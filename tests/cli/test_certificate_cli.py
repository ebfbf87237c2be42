"""certificate and apply --interval through the CLI: outputs, and bad input as one line."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from conftest import assert_one_line_error, invoke

from fsdecouple import decouple_frame, load_model
from fsdecouple.sim.simulate import simulate


@pytest.fixture(scope="module")
def fitted(sim_model_file):
    return sim_model_file  # `fsdecouple fit` of the simulated set, once a session


def test_certificate_json_and_html(fitted, sim_dir, tmp_path):
    doc = json.loads(invoke(["certificate", fitted, sim_dir / "calibration", "--json"]).stdout)
    assert doc["format"] == "fsdecouple.certificate"
    assert {"axis", "load", "metric", "value"} == set(doc["records"][0])
    assert {r["metric"] for r in doc["records"]} == {"b", "b_prime", "f_c", "U"}
    out = tmp_path / "certificate.html"
    config = tmp_path / "lab.yaml"
    config.write_text("serial: SN-0042\nreference: deadweights, DKD-K-12345\n"
                      "reference_uncertainty: 0.002\nenvironment: {temperature: 21.3 °C}\n")
    r = invoke(["certificate", fitted, sim_dir / "calibration", "-c", config, "-o", out])
    assert "certificate written" in r.stdout
    html = out.read_text()
    for needle in ("SN-0042", "DKD-K-12345", "0.002 % (k = 2)", "21.3 °C", "@page{size:A4",
                   "Uncertainty budget of x", 'id="u-z"'):
        assert needle in html, needle


def test_bad_reference_uncertainty_and_a_foreign_set_are_one_line_and_write_nothing(
        fitted, sim_dir, tmp_path):
    out = tmp_path / "c.html"
    config = tmp_path / "neg.yaml"
    config.write_text("reference_uncertainty: -0.05\n")
    r = invoke(["certificate", fitted, sim_dir / "calibration", "-c", config, "-o", out], 2)
    assert_one_line_error(r, "reference_uncertainty", "-0.05")
    other = tmp_path / "other"
    simulate(other, seed=11)
    r = invoke(["certificate", fitted, other / "calibration", "-o", out], 2)
    assert_one_line_error(r, "does not match the model file")
    config.write_text("full_scale: {x: 50, y: 100, z: 150}\n")
    r = invoke(["certificate", fitted, sim_dir / "calibration", "-c", config, "-o", out], 2)
    assert_one_line_error(r, "full_scale is not the model's")
    assert not out.exists()


def test_apply_interval_adds_bounds_and_decouple_frame_gives_the_same(fitted, sim_dir, tmp_path):
    out = tmp_path / "f.csv"
    invoke(["apply", fitted, sim_dir / "task_voltages.csv", "-o", out, "--tare", 200,
            "--interval", 0.95, "--round-trip"])
    got = pd.read_csv(out)
    assert list(got.columns[4:]) == ["fx", "fy", "fz", "fx_lo", "fx_hi", "fy_lo", "fy_hi",
                                     "fz_lo", "fz_hi", "status"]
    width = got["fx_hi"] - got["fx_lo"]
    assert (width > 0).all() and np.ptp(width) < 1e-9  # one width per component
    frame = pd.read_csv(sim_dir / "task_voltages.csv")
    same = decouple_frame(load_model(fitted), frame, tare=200, interval=0.95)
    for c in ("fx", "fx_lo", "fz_hi"):
        assert same[c].to_numpy() == pytest.approx(got[c].to_numpy(), rel=0, abs=1e-9)
    truth = pd.read_csv(sim_dir / "task_forces.csv")
    inside = ((truth["fy"] >= got["fy_lo"]) & (truth["fy"] <= got["fy_hi"])).mean()
    assert inside > 0.8  # one log; the coverage over seeds is test_coverage.py's


@pytest.mark.parametrize("p", ["1.5", "0", "-0.2"])
def test_interval_outside_0_1_is_one_line_and_writes_nothing(fitted, sim_dir, tmp_path, p):
    out = tmp_path / "f.csv"
    r = invoke(["apply", fitted, sim_dir / "task_voltages.csv", "-o", out, "--tare", 200,
                "--interval", p], 2)
    assert_one_line_error(r, f"--interval {float(p)!r}")
    assert not out.exists()


def test_export_says_the_header_has_no_intervals(fitted, tmp_path):
    r = invoke(["export", fitted, "-o", tmp_path / "d.h"])
    assert "apply --interval's bounds are not in it" in r.stdout
