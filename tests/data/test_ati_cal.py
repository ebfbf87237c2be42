"""ATI calibration files in (issue 31, items 4 and 7): `fsdecouple import FILE.cal`.

The reference is :class:`Atidaq` (tests/atidaq_reference.py), an independent
double-precision reimplementation of ATI's DAQ F/T library (ATIDAQ: ftconfig.c
reads the file and builds the working matrix, ftrt.c biases and converts), written
from its equations; nothing of it is shared with the package.  The fixtures
(tests/fixtures/ati/, written by make_fixtures.py) are in ATI's real format:
NumGages, Axis rows with values/max/scale, BasicTransform with every term, UserAxis
rows, N/N-m/m, N/N-mm/mm and lbf/lbf-in/in with temperature compensation.
"""

from __future__ import annotations

import time
import xml.etree.ElementTree as ET  # the fixtures are ours: trusted input
from pathlib import Path

import numpy as np
import pytest
from atidaq_reference import Atidaq
from conftest import invoke

from fsdecouple.core.modelfile import load_model
from fsdecouple.data.ati_model import import_cal
from fsdecouple.errors import InputError

FIXTURES = Path(__file__).resolve().parent.parent / "fixtures" / "ati"
CAL_FILES = ("FT_gamma_like.cal", "FT_nano_like.cal", "FT_tc.cal")

def gauge_log(path: Path, ref: Atidaq, rows: int, seed: int) -> np.ndarray:
    """A log of gauge voltages (+ thermistor when compensated): 20 unloaded rows first, then
    combined loads up to 0.8 of full scale."""
    rng = np.random.default_rng(seed)
    f = rng.uniform(-0.8, 0.8, (rows, len(ref.max))) * np.asarray(ref.max)
    f[:20] = 0.0
    g = f @ np.linalg.pinv(ref.working).T + rng.normal(0, 1e-4, (rows, ref.n)) + 0.1
    cols = [f"g{i}" for i in range(ref.n)]
    if ref.tc:
        g = np.column_stack([g, ref.therm + rng.uniform(-0.3, 0.3, rows)])
        cols.append("thermistor")
    lines = ["t," + ",".join(cols)]
    lines += [f"{i}," + ",".join(repr(float(x)) for x in row) for i, row in enumerate(g)]
    path.write_text("\n".join(lines) + "\n")
    return g


def read_forces(path: Path, n: int) -> np.ndarray:
    import pandas as pd

    df = pd.read_csv(path)
    assert (df["status"] == "ok").all()
    return df[[c.lower() for c in ("fx", "fy", "fz", "tx", "ty", "tz")][:n]].to_numpy()


@pytest.mark.parametrize("name", CAL_FILES)
def test_import_decouples_as_atidaq(name, tmp_path):
    """apply --zero/--tare of the imported model = ATIDAQ's Bias + ConvertToFT, 1e-9 of max."""
    cal = FIXTURES / name
    ref = Atidaq(cal)
    out = tmp_path / "model.json"
    invoke(["import", cal, "-o", out])
    model = load_model(out)
    assert model.method == "linear" and model.layout.labels == ("fx", "fy", "fz", "tx", "ty", "tz")
    assert list(model.settings.full_scale) == ref.max
    assert model.layout.outputs[:ref.n] == tuple(f"g{i}" for i in range(ref.n))
    assert (model.temperature is not None) == ref.tc
    g = gauge_log(tmp_path / "log.csv", ref, 200, seed=len(name))
    tol = 1e-9 * np.asarray(ref.max)  # the bound; the CSV keeps 1e-10 F.S.
    # --zero: one bias vector (NumGages + 1 values with temperature compensation)
    zero = g[7]
    invoke(["apply", out, tmp_path / "log.csv", "-o", tmp_path / "f.csv", "--zero",
            ",".join(repr(float(v)) for v in zero)])
    ref.bias(list(zero))
    expected = np.array([ref.convert(list(row)) for row in g])
    assert np.all(np.abs(read_forces(tmp_path / "f.csv", 6) - expected) <= tol)
    # --tare 20: the bias of the mean of the first 20 rows
    invoke(["apply", out, tmp_path / "log.csv", "-o", tmp_path / "t.csv", "--tare", "20"])
    ref.bias(list(g[:20].mean(axis=0)))
    expected = np.array([ref.convert(list(row)) for row in g])
    assert np.all(np.abs(read_forces(tmp_path / "t.csv", 6) - expected) <= tol)


def test_without_a_bias_atidaq_subtracts_nothing(tmp_path):
    """No --zero/--tare: ATIDAQ's bias vectors are 0 until Bias() (ResetDefaults), even with
    temperature compensation (TCbias_vector = 0, not TempComp(0, 0))."""
    ref = Atidaq(FIXTURES / "FT_tc.cal")
    model = import_cal(FIXTURES / "FT_tc.cal")
    g = gauge_log(tmp_path / "log.csv", ref, 50, seed=3)
    u = model.zero_corrected(g, np.zeros(g.shape[1]))
    expected = np.array([ref.convert(list(row)) for row in g])
    assert np.abs(model.decouple(u) - expected).max() <= 1e-12 * max(ref.max)


def test_temperature_compensation_changes_the_forces():
    """The correction is not a no-op: a thermistor 0.3 V off T0 moves the forces."""
    model = import_cal(FIXTURES / "FT_tc.cal")
    g = np.array([[0.2, -0.1, 0.3, 0.05, -0.2, 0.1, model.temperature.t0]])
    warm = g.copy()
    warm[0, -1] += 0.3
    off = np.zeros(7)
    f0 = model.decouple(model.zero_corrected(g, off))
    f1 = model.decouple(model.zero_corrected(warm, off))
    assert np.abs(f1 - f0).max() > 1e-3 * max(model.settings.full_scale)


@pytest.mark.parametrize("name", CAL_FILES)
def test_axis_rows_agree_with_user_axis_rows(name):
    """ATI prints UserAxis = T_basic (Axis / scale) to 5 decimals: the working matrix
    built from the Axis rows (as ATIDAQ) must agree with them to that rounding."""
    root = ET.parse(FIXTURES / name).getroot()
    user = np.array([[float(v) for v in e.get("values").split()] for e in root.iter("UserAxis")])
    model = import_cal(FIXTURES / name)
    w = model.matrix[:, :user.shape[1]]
    assert np.abs(w - user).max() <= 0.5e-5 * (1 + 1e-9)
    assert model.warnings == []


def test_bias_slope_and_gain_slope_signs():
    """b = -BiasSlope, g = -GainSlope, T0 = Thermistor (ATIDAQ's TempComp)."""
    root = ET.parse(FIXTURES / "FT_tc.cal").getroot()
    bs = [float(v) for v in root.find(".//BiasSlope").get("values").split()]
    gs = [float(v) for v in root.find(".//GainSlope").get("values").split()]
    t = import_cal(FIXTURES / "FT_tc.cal").temperature
    assert t.b[:6] == pytest.approx(-np.array(bs), abs=0) and t.g[:6] == pytest.approx(-np.array(gs))
    assert t.t0 == float(root.find(".//Thermistor").get("value"))


def test_import_summary_and_show(tmp_path):
    out = tmp_path / "m.json"
    r = invoke(["import", FIXTURES / "FT_nano_like.cal", "-o", out])
    assert "6 gauges" in r.stdout and "fx 25 N" in r.stdout and "tz 250 N·mm" in r.stdout
    shown = invoke(["show", out]).stdout
    assert "Factory calibration matrix" in shown and "g5" in shown


def test_more_than_one_calibration_is_said_and_chosen(tmp_path):
    text = (FIXTURES / "FT_gamma_like.cal").read_text()
    start, end = text.index("\t<Calibration"), text.index("</Calibration>") + len("</Calibration>")
    second = text[start:end].replace('max="130"', 'max="260"')
    two = tmp_path / "two.cal"
    two.write_text(text[:end] + "\r\n" + second + text[end:])
    assert list(import_cal(two).settings.full_scale)[0] == 130
    assert "holds 2 calibrations" in import_cal(two).warnings[0]
    assert list(import_cal(two, 2).settings.full_scale)[0] == 260
    with pytest.raises(InputError, match="calibration 3 asked for, the file holds 2"):
        import_cal(two, 3)


# --- bad input (item 7): exit 2, one line naming the file and the element, nothing written ---

def refused(tmp_path, text: str | bytes, match: str, name: str = "bad.cal") -> str:
    bad = tmp_path / name
    (bad.write_bytes if isinstance(text, bytes) else bad.write_text)(text)
    out = tmp_path / "model.json"
    start = time.monotonic()
    r = invoke(["import", bad, "-o", out], code=2)
    assert time.monotonic() - start < 5.0
    err = r.stderr.strip()
    assert len(err.splitlines()) == 1 and name in err and "Traceback" not in err, err
    assert match in err, err
    assert not out.exists()
    return err


def test_truncated_file_is_refused(tmp_path):
    text = (FIXTURES / "FT_gamma_like.cal").read_text()
    refused(tmp_path, text[:text.index('<Axis Name="Tx"') + 20], "truncated inside element <Calibration>")


def test_a_row_with_the_wrong_number_of_values(tmp_path):
    text = (FIXTURES / "FT_gamma_like.cal").read_text()
    start = text.index('<Axis Name="Fy" values="') + len('<Axis Name="Fy" values="')
    end = text.index('"', start)
    short = " ".join(text[start:end].split()[:5])
    refused(tmp_path, text[:start] + short + text[end:],
            'element <Axis Name="Fy">: values holds 5 numbers, expected 6')


def test_a_value_that_is_no_number(tmp_path):
    text = (FIXTURES / "FT_tc.cal").read_text().replace('<Thermistor value="', '<Thermistor value="x')
    refused(tmp_path, text, "element <Thermistor>")


def test_not_xml(tmp_path):
    refused(tmp_path, "t,g0,g1\n0,0.1,0.2\n", "not well-formed XML")


def test_not_an_ati_file(tmp_path):
    refused(tmp_path, '<?xml version="1.0"?><config a="1"/>', "root element <config>")


def test_entity_expansion_bomb(tmp_path):
    lol = ['<!ENTITY lol "lol">'] + [f'<!ENTITY lol{i} "{("&lol" + str(i - 1) + ";") * 10}">'
                                      if i > 1 else '<!ENTITY lol1 "&lol;&lol;&lol;&lol;&lol;">'
                                      for i in range(1, 10)]
    bomb = ('<?xml version="1.0"?>\n<!DOCTYPE FTSensor [\n' + "\n".join(lol) + "\n]>\n"
            '<FTSensor Serial="&lol9;" NumGages="6"/>\n')
    refused(tmp_path, bomb, "<!DOCTYPE")


def test_unknown_units_and_missing_max(tmp_path):
    text = (FIXTURES / "FT_gamma_like.cal").read_text()
    refused(tmp_path, text.replace('ForceUnits="N"', 'ForceUnits="furlong"'),
            "element <Calibration>: ForceUnits 'furlong'")
    refused(tmp_path, text.replace('max="400"', 'max="0"'), 'element <Axis Name="Fz">: max is 0')


def test_gauge_count_not_matching_the_log(tmp_path):
    out = tmp_path / "model.json"
    invoke(["import", FIXTURES / "FT_gamma_like.cal", "-o", out])
    log = tmp_path / "log.csv"
    log.write_text("t,g0,g1,g2,g3,g4,g5,g6\n0,0.1,0.2,0.3,0.4,0.5,0.6,0.7\n")
    r = invoke(["apply", out, log, "-o", tmp_path / "f.csv"], code=2)
    assert "column 'g6'" in r.stderr and "NumGages = 6" in r.stderr
    assert not (tmp_path / "f.csv").exists()
    log.write_text("t,g0,g1,g2,g3,g4\n0,0.1,0.2,0.3,0.4,0.5\n")
    r = invoke(["apply", out, log, "-o", tmp_path / "f.csv"], code=2)
    assert "g5" in r.stderr and not (tmp_path / "f.csv").exists()


def test_temperature_column_holding_text(tmp_path):
    out = tmp_path / "model.json"
    invoke(["import", FIXTURES / "FT_tc.cal", "-o", out])
    log = tmp_path / "log.csv"
    log.write_text("g0,g1,g2,g3,g4,g5,thermistor\n0.1,0.2,0.3,0.4,0.5,0.6,1.2\n"
                   "0.1,0.2,0.3,0.4,0.5,0.6,warm\n")
    r = invoke(["apply", out, log, "-o", tmp_path / "f.csv"], code=2)
    assert "row 3" in r.stderr and "thermistor" in r.stderr and "warm" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "f.csv").exists()


def test_a_log_without_the_thermistor_column(tmp_path):
    out = tmp_path / "model.json"
    invoke(["import", FIXTURES / "FT_tc.cal", "-o", out])
    log = tmp_path / "log.csv"
    log.write_text("g0,g1,g2,g3,g4,g5\n0.1,0.2,0.3,0.4,0.5,0.6\n")
    r = invoke(["apply", out, log, "-o", tmp_path / "f.csv"], code=2)
    assert "thermistor" in r.stderr and "--temperature VALUE" in r.stderr
    assert not (tmp_path / "f.csv").exists()


def test_report_and_certificate_refuse_a_factory_matrix_in_one_line(tmp_path):
    out = tmp_path / "model.json"
    invoke(["import", FIXTURES / "FT_gamma_like.cal", "-o", out])
    r = invoke(["report", out, "-o", tmp_path / "r.html"], code=2)
    assert "imported factory matrix" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "r.html").exists()


def test_validate_refuses_a_temperature_model(tmp_path):
    """A set zero-corrected sweep by sweep carries no absolute thermistor reading: refused
    in one line, never scored without its compensation."""
    out = tmp_path / "model.json"
    invoke(["import", FIXTURES / "FT_tc.cal", "-o", out])
    r = invoke(["validate", out, FIXTURES], code=2)
    assert "corrects its outputs for temperature" in r.stderr


def test_temperature_option_for_a_log_without_the_thermistor(tmp_path):
    """--temperature V: the log's rows decoupled as ATIDAQ does with the thermistor at V;
    refused where the log has the column or the model has no temperature terms."""
    ref = Atidaq(FIXTURES / "FT_tc.cal")
    out = tmp_path / "model.json"
    invoke(["import", FIXTURES / "FT_tc.cal", "-o", out])
    g = gauge_log(tmp_path / "full.csv", ref, 60, seed=9)
    lines = (tmp_path / "full.csv").read_text().splitlines()
    (tmp_path / "log.csv").write_text("\n".join(",".join(x.split(",")[:-1]) for x in lines) + "\n")
    t = ref.therm + 0.2
    invoke(["apply", out, tmp_path / "log.csv", "-o", tmp_path / "f.csv", "--tare", "20",
            "--temperature", repr(t)])
    g[:, -1] = t
    ref.bias(list(g[:20].mean(axis=0)))
    expected = np.array([ref.convert(list(row)) for row in g])
    assert np.all(np.abs(read_forces(tmp_path / "f.csv", 6) - expected) <= 1e-9 * np.asarray(ref.max))
    r = invoke(["apply", out, tmp_path / "full.csv", "-o", tmp_path / "x.csv", "--temperature",
                "1.0"], code=2)
    assert "would replace" in r.stderr and not (tmp_path / "x.csv").exists()
    plain = tmp_path / "plain.json"
    invoke(["import", FIXTURES / "FT_gamma_like.cal", "-o", plain])
    r = invoke(["apply", plain, tmp_path / "log.csv", "-o", tmp_path / "x.csv", "--temperature",
                "1.0"], code=2)
    assert "no temperature terms" in r.stderr


def test_ati_unit_names(tmp_path):
    """ATI's names become fsdecouple's units (lb -> lbf, klb -> klbf, kg -> kgf, N-mm -> N·mm)."""
    text = (FIXTURES / "FT_gamma_like.cal").read_text()
    for ati, force in (("lb", "lbf"), ("klb", "klbf"), ("kg", "kgf"), ("g", "gf"), ("kN", "kN")):
        path = tmp_path / f"{ati}.cal"
        path.write_text(text.replace('ForceUnits="N"', f'ForceUnits="{ati}"')
                        .replace('TorqueUnits="N-m"', 'TorqueUnits="N-mm"'))
        units = import_cal(path).settings.units
        assert units.load_of(0) == force and units.load_of(5) == "N·mm"
