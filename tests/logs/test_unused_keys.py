"""apply -c: a key apply does not read from a config is refused or warned about (issue 34).

apply takes the model's own settings and reads only how the log is laid out (columns,
scale, csv, limits, units) from a config: a rotation the model does not have was ignored
without a word, so the forces came out in the sensor's frame.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from conftest import SAMPLE, assert_one_line_error, invoke

LOG = SAMPLE / "task_voltages.csv"


def test_a_rotation_the_model_lacks_is_refused(sample_model, tmp_path):
    cfg = tmp_path / "rot.yaml"
    cfg.write_text("rotation: [[0, -1, 0], [1, 0, 0], [0, 0, 1]]\n")
    out = tmp_path / "f.csv"
    r = invoke(["apply", sample_model, LOG, "-c", cfg, "--tare", "200", "-o", out], 2)
    assert_one_line_error(r, "rotation", "refit with this config")
    assert not out.exists()


def test_a_fit_only_key_stated_otherwise_is_warned_about_and_a_log_layout_is_read(
        sample_model, tmp_path):
    plain = tmp_path / "plain.csv"
    invoke(["apply", sample_model, LOG, "--tare", "200", "-o", plain])
    renamed = tmp_path / "log.csv"
    pd.read_csv(LOG).rename(columns={"ux": "a", "uy": "b", "uz": "c"}).to_csv(renamed, index=False)
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("svr: {C: 10}\ncolumns: {ux: a, uy: b, uz: c}\n")
    out = tmp_path / "f.csv"
    r = invoke(["apply", sample_model, renamed, "-c", cfg, "--tare", "200", "-o", out])
    assert "config's svr differs from the model's" in r.stderr and "not used" in r.stderr
    # the columns were read from the config, the forces are the model's own
    got, want = pd.read_csv(out), pd.read_csv(plain)
    np.testing.assert_array_equal(got[["fx", "fy", "fz"]], want[["fx", "fy", "fz"]])


def test_the_calibrations_own_keys_are_no_news(sample_model, tmp_path):
    cfg = tmp_path / "cfg.yaml"
    # zero: rows is what the sample's model used, by default (its file leaves zero unsaid)
    cfg.write_text("sensor: paper-3axis\nfull_scale: {x: 100, y: 100, z: 150}\nrotation: null\n"
                   "svr: {C: 1000, epsilon: 0.0001, delta2: 1.0}\nzero: rows\n")
    r = invoke(["apply", sample_model, LOG, "-c", cfg, "--tare", "200", "-o", tmp_path / "f.csv"])
    assert "differs" not in r.stderr, r.stderr


def test_a_zero_other_than_the_models_is_news(sample_model, tmp_path):
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("zero: fit\n")
    r = invoke(["apply", sample_model, LOG, "-c", cfg, "--tare", "200", "-o", tmp_path / "f.csv"])
    assert "config's zero differs from the model's" in r.stderr
