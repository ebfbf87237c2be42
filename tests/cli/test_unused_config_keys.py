"""validate, certificate and apply to many logs with -c: a key the command does not read
from a config is refused (it would change the forces) or warned about (fit only), as
apply -c to one log is (issue 34; schema.READS says which keys each command reads)."""

from __future__ import annotations

import shutil

import pytest
from conftest import SAMPLE, assert_one_line_error, invoke

ROTATION = "rotation: [[0, -1, 0], [1, 0, 0], [0, 0, 1]]\n"
SVR = "svr: {C: 10}\n"
# the defaults both models were fitted with, stated: no news
SAME = ("sensor: paper-3axis\nfull_scale: {x: 100, y: 100, z: 150}\nrotation: null\n"
        "svr: {C: 1000, epsilon: 0.0001, delta2: 1.0}\n")


def _cfg(tmp_path, text):
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text(text)
    return cfg


def _validate(model, tmp_path, text, code=0):
    out = tmp_path / "v.json"
    r = invoke(["validate", model, SAMPLE / "calibration", "-c", _cfg(tmp_path, text),
                "-o", out, "--force"], code)
    return r, out


def test_validate_refuses_a_rotation_warns_of_svr_and_is_silent_on_the_models_own(
        sample_model, tmp_path):
    r, out = _validate(sample_model, tmp_path, ROTATION, 2)
    assert_one_line_error(r, "rotation", "refit with this config")
    assert not out.exists()
    r, _ = _validate(sample_model, tmp_path, SVR)
    assert "config's svr differs from the model's" in r.stderr and "not used" in r.stderr
    r, _ = _validate(sample_model, tmp_path, SAME)
    assert "differs" not in r.stderr, r.stderr


def _certificate(model, calib, tmp_path, text, code=0):
    out = tmp_path / "c.html"
    r = invoke(["certificate", model, calib, "-c", _cfg(tmp_path, text), "-o", out, "--force"], code)
    return r, out


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_certificate_refuses_a_rotation_warns_of_svr_and_reads_its_lab_keys(
        sim_model_file, sim_dir, tmp_path):
    calib = sim_dir / "calibration"
    r, out = _certificate(sim_model_file, calib, tmp_path, ROTATION, 2)
    assert_one_line_error(r, "rotation", "refit with this config")
    assert not out.exists()
    r, out = _certificate(sim_model_file, calib, tmp_path, SVR)
    assert "config's svr differs from the model's" in r.stderr and "not used" in r.stderr
    assert "svr" not in out.read_text()  # about the run, not the sensor: not on the certificate
    # zero left unsaid and the lab's own keys are the certificate's: no news
    r, out = _certificate(sim_model_file, calib, tmp_path, SAME + "serial: SN-0042\n")
    assert "differs" not in r.stdout + r.stderr, r.stdout
    assert "SN-0042" in out.read_text()


def test_apply_to_many_logs_refuses_a_rotation_the_model_lacks(sample_model, tmp_path):
    logs = tmp_path / "logs"
    logs.mkdir()
    for name in ("a.csv", "b.csv"):
        shutil.copy(SAMPLE / "task_voltages.csv", logs / name)
    out = tmp_path / "out"
    r = invoke(["apply", sample_model, logs / "a.csv", logs / "b.csv", "-c",
                _cfg(tmp_path, ROTATION), "--tare", "200", "-o", f"{out}/"], 2)
    assert_one_line_error(r, "rotation", "refit with this config")
    assert not out.exists()


def test_apply_to_many_logs_warns_of_svr_and_is_silent_on_the_models_own(sample_model, tmp_path):
    logs = tmp_path / "logs"
    logs.mkdir()
    for name in ("a.csv", "b.csv"):
        shutil.copy(SAMPLE / "task_voltages.csv", logs / name)
    for i, (text, news) in enumerate(((SVR, True), (SAME, False))):
        r = invoke(["apply", sample_model, logs / "a.csv", logs / "b.csv", "-c",
                    _cfg(tmp_path, text), "--tare", "200", "-o", f"{tmp_path / f'out{i}'}/"])
        assert ("config's svr differs from the model's" in r.stderr) is news, r.stderr
