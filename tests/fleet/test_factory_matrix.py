"""An imported factory matrix (issue 31, item 4) in validate and compare: the factory
calibration scored on the user's own set, and factory against recalibration.

The user's set is simulated from a "true" matrix W_true (the factory's W perturbed by
1 %, constant offsets per repetition, noise 1e-7 V), so every figure has a closed form:
validate's error of W on a point is |W W_true^-1 F - F| / F_FS, and compare's force
drift over loads within +-F_FS is, for two matrices, attained at a corner of that box:
max_a sum_b |M_ab| F_FS,b / F_FS,a with M = (W_new - W_old) W_old^-1.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import invoke

from fsdecouple.data.ati_model import import_cal

FIXTURES = Path(__file__).resolve().parent.parent / "fixtures" / "ati"
CONFIG = """sensor: recalibrated
components: [fx, fy, fz, tx, ty, tz]
outputs: [g0, g1, g2, g3, g4, g5]
full_scale: {fx: 130, fy: 130, fz: 400, tx: 10, ty: 10, tz: 10}
units:
  load: {fx: N, fy: N, fz: N, tx: N·m, ty: N·m, tz: N·m}
  output: V
min_repetitions: 3
"""


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    d = tmp_path_factory.mktemp("lab")
    factory = import_cal(FIXTURES / "FT_gamma_like.cal")
    invoke(["import", FIXTURES / "FT_gamma_like.cal", "-o", d / "factory.json"])
    rng = np.random.default_rng(1)
    w_true = factory.matrix * (1 + rng.normal(0, 0.01, factory.matrix.shape))
    fs = np.asarray(factory.settings.full_scale)
    (d / "set").mkdir()
    for rep in (1, 2, 3):
        off = rng.normal(0, 0.05, 6)
        lines = ["axis,fx,fy,fz,tx,ty,tz,g0,g1,g2,g3,g4,g5"]
        for a, lab_ in enumerate(factory.layout.labels):
            for s in np.linspace(-1, 1, 11):
                f = np.zeros(6)
                f[a] = s * fs[a]
                u = np.linalg.solve(w_true, f) + off + rng.normal(0, 1e-7, 6)
                lines.append(lab_ + "," + ",".join(repr(float(v)) for v in (*f, *u)))
        (d / "set" / f"rep{rep}.csv").write_text("\n".join(lines) + "\n")
    (d / "sensor.yaml").write_text(CONFIG, encoding="utf-8")
    return d, factory, w_true, fs


def test_validate_scores_the_factory_matrix_on_the_users_set(lab, tmp_path):
    d, factory, w_true, fs = lab
    r = invoke(["validate", d / "factory.json", d / "set", "--json"])
    doc = json.loads(r.stdout)
    assert {rec["method"] for rec in doc["records"]} == {"model"}  # nothing fitted beside it
    # its thermistor-less 6 x 6 W has no initial rows, and the legend says none (the
    # key said "f = P u" for a thermistor's seventh output, read as M > N gauges)
    assert doc["initial"] is None
    assert "initial:" not in invoke(["validate", d / "factory.json", d / "set"]).stdout
    for a, axis in enumerate(factory.layout.labels):
        f = np.zeros((11, 6))
        f[:, a] = np.linspace(-1, 1, 11) * fs[a]
        err = np.abs(f @ np.linalg.solve(w_true.T, factory.matrix.T) - f) / fs  # W W_true^-1 F - F
        got = next(rec["value"] for rec in doc["records"] if rec["axis"] == axis
                   and rec["metric"] == "max_error" and rec["range"] == "calibrated")
        # the zero correction of a set with noise 1e-7 V: ~1e-6 of full scale
        assert got == pytest.approx(err.max(), abs=1e-5), axis


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_compare_factory_against_recalibration(lab, tmp_path):
    d, factory, w_true, fs = lab
    invoke(["fit", d / "set", "-c", d / "sensor.yaml", "-o", tmp_path / "recal.json",
            "--method", "linear"])
    from fsdecouple.fleet.drift import compare

    doc = compare(d / "factory.json", tmp_path / "recal.json")
    m = (w_true - factory.matrix) @ np.linalg.inv(factory.matrix)
    expected = 100 * (np.abs(m) @ fs) / fs
    got = np.array([doc["components"][a]["force_max_pct"] for a in factory.layout.labels])
    # the recalibration's least-squares matrix is W_true to the noise, 1e-7 V
    assert got == pytest.approx(expected, abs=1e-3)
    assert all(c["slope_change_pct"] is None and c["chi_max_pct"] == {}
               for c in doc["components"].values())
    assert doc["en"] is not None and "factory matrix" in doc["en_note"]
    r = invoke(["compare", d / "factory.json", tmp_path / "recal.json"], code=1)  # |E_n| > 1
    assert "factory matrix with no stated uncertainty" in r.stdout + r.stderr


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_compare_factory_torques_against_a_recalibration_naming_moments(lab, tmp_path):
    """ATI names torques tx..tz, fsdecouple's six-axis configs moments mx..mz: one sensor's
    components in one order, compared by position (a KeyError traceback before); other
    names are refused in one line."""
    d, factory, w_true, fs = lab
    moments = tmp_path / "set"
    moments.mkdir()
    for rep in sorted((d / "set").iterdir()):
        lines = rep.read_text().splitlines()
        lines[0] = lines[0].replace(",tx,ty,tz,", ",mx,my,mz,")
        body = [line.replace("t", "m", 1) if line[:1] == "t" else line for line in lines[1:]]
        (moments / rep.name).write_text("\n".join([lines[0], *body]) + "\n")
    cfg = tmp_path / "sensor.yaml"
    cfg.write_text(CONFIG.replace("tx", "mx").replace("ty", "my").replace("tz", "mz"))
    invoke(["fit", moments, "-c", cfg, "-o", tmp_path / "recal.json", "--method", "linear"])
    r = invoke(["compare", d / "factory.json", tmp_path / "recal.json", "--json"], code=1)
    doc = json.loads(r.stdout)
    m = (w_true - factory.matrix) @ np.linalg.inv(factory.matrix)
    got = np.array([doc["components"][a]["force_max_pct"] for a in factory.layout.labels])
    assert got == pytest.approx(100 * (np.abs(m) @ fs) / fs, abs=1e-3)
    assert set(doc["en"]) == set(factory.layout.labels)
    other = tmp_path / "other.yaml"
    other.write_text(CONFIG.replace("tx", "qx").replace("ty", "qy").replace("tz", "qz"))
    for rep in moments.iterdir():
        rep.write_text(rep.read_text().replace("m", "q"))
    invoke(["fit", moments, "-c", other, "-o", tmp_path / "q.json", "--method", "linear"])
    r = invoke(["compare", d / "factory.json", tmp_path / "q.json"], code=2)
    assert "its components are fx, fy, fz, qx, qy, qz" in r.stderr
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_compare_reports_the_drift_of_the_temperature_terms(tmp_path):
    """Two temperature-compensated files: b and g change by minus the change of ATI's
    BiasSlope and GainSlope (b = -BS, g = -GS), T0 by that of Thermistor."""
    import xml.etree.ElementTree as ET

    text = (FIXTURES / "FT_tc.cal").read_text()
    root = ET.fromstring(text.encode())
    bs = [float(v) for v in root.find(".//BiasSlope").get("values").split()]
    gs = [float(v) for v in root.find(".//GainSlope").get("values").split()]
    therm = float(root.find(".//Thermistor").get("value"))
    bs2, gs2 = [v * 1.1 for v in bs], [v - 1e-4 for v in gs]
    new = text.replace(root.find(".//BiasSlope").get("values"), " ".join(map(repr, bs2)))
    new = new.replace(root.find(".//GainSlope").get("values"), " ".join(map(repr, gs2)))
    new = new.replace(f'<Thermistor value="{therm!r}"', '<Thermistor value="1.5"')
    (tmp_path / "new.cal").write_text(new)
    invoke(["import", FIXTURES / "FT_tc.cal", "-o", tmp_path / "a.json"])
    invoke(["import", tmp_path / "new.cal", "-o", tmp_path / "b.json"])
    r = invoke(["compare", tmp_path / "a.json", tmp_path / "b.json", "--json"])
    doc = json.loads(r.stdout)
    t = doc["temperature"]
    assert t["t0_change"] == pytest.approx(1.5 - therm)
    for i in range(6):
        assert t["b_change"][f"g{i}"] == pytest.approx(-(bs2[i] - bs[i]), rel=1e-9, abs=1e-15)
        assert t["g_change"][f"g{i}"] == pytest.approx(-(gs2[i] - gs[i]), rel=1e-9, abs=1e-15)
    # the matrices are the same: no force drift; no E_n without any stated uncertainty
    assert all(c["force_max_pct"] < 1e-9 for c in doc["components"].values())
    assert doc["en"] is None and "factory matrices" in doc["en_note"]
    shown = invoke(["compare", tmp_path / "a.json", tmp_path / "b.json"]).stdout
    assert "temperature terms, new - old" in shown
