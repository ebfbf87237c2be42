"""ATI calibration files out (issue 31, item 5): `fsdecouple export model.json -o sensor.cal`.

What the written file means is read back by :class:`Atidaq` (tests/atidaq_reference.py),
an independent reimplementation of ATIDAQ's equations: its forces must be the
model's own (``model.decouple``, with ``apply``'s zero) for an imported factory
matrix (round trip) and for a linear model fitted on the six-axis sample.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from atidaq_reference import Atidaq
from conftest import SAMPLE, invoke
from test_export import build, decouple, needs_cc

from fsdecouple import load_config
from fsdecouple.core.modelfile import load_model, save_model
from fsdecouple.data.ati_model import import_cal
from fsdecouple.data.calibration import load_calibration
from fsdecouple.evaluation.calibrate import fit as calibrate
from fsdecouple.wrench import Frame

FIXTURES = Path(__file__).resolve().parent.parent / "fixtures" / "ati"
SIX = SAMPLE / "six_axis"


@pytest.fixture(scope="module")
def six_linear():
    """fit --method linear on the six-axis sample (N and N·m, volts)."""
    settings = load_config(SIX / "sensor.yaml")
    model = calibrate(load_calibration(SIX / "calibration", settings), settings, method="linear",
                      verdict=False)
    assert model.method == "linear"
    return model


def random_outputs(model, rng, rows=500):
    """Outputs spanning the model's calibrated range (inputs of f = C u)."""
    f = rng.uniform(-1, 1, (rows, model.n_components)) * np.asarray(model.settings.full_scale)
    return f @ np.linalg.pinv(model.matrix).T


@pytest.mark.parametrize("name", ["FT_gamma_like.cal", "FT_nano_like.cal", "FT_tc.cal"])
def test_import_export_round_trip(name, tmp_path):
    """import -> export -> ATIDAQ reads the same forces as from the original file (1e-12
    of max: both are double); import again gives the same model."""
    json1, cal2, json2 = tmp_path / "a.json", tmp_path / "b.cal", tmp_path / "b.json"
    invoke(["import", FIXTURES / name, "-o", json1])
    r = invoke(["export", json1, "-o", cal2])
    assert "wrote" in r.stdout and cal2.exists()
    invoke(["import", cal2, "-o", json2])
    a, b = load_model(json1), load_model(json2)
    assert np.array_equal(a.matrix, b.matrix)
    assert list(a.settings.full_scale) == list(b.settings.full_scale)
    assert a.settings.units == b.settings.units
    if a.temperature is not None:
        assert np.array_equal(a.temperature.b, b.temperature.b)
        assert np.array_equal(a.temperature.g, b.temperature.g)
        assert a.temperature.t0 == b.temperature.t0
    orig, back = Atidaq(FIXTURES / name), Atidaq(cal2)
    rng = np.random.default_rng(5)
    width = orig.n + 1
    at_t0 = np.array([0.0] * orig.n + [orig.therm])
    bias = rng.normal(0, 0.05, width) + at_t0
    for ref in (orig, back):
        ref.bias(list(bias))
    for v in rng.normal(0, 0.5, (50, width)) + at_t0:
        assert np.allclose(back.convert(list(v)), orig.convert(list(v)), rtol=0,
                           atol=1e-12 * max(orig.max))
    # UserAxis rows agree with the Axis rows (ATIDAQ's working matrix), digit for digit
    root = ET.parse(cal2).getroot()
    user = np.array([[float(x) for x in e.get("values").split()] for e in root.iter("UserAxis")])
    assert np.array_equal(user, back.working)
    assert [e.get("Name") for e in root.iter("Axis")] == ["Fx", "Fy", "Fz", "Tx", "Ty", "Tz"]


@pytest.mark.parametrize("frame", [None, Frame(((0.0, -1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
                                               (0.1, 0.0, 0.25))])
@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_fitted_linear_model_reads_back_in_atidaq(six_linear, frame, tmp_path):
    """A fitted linear six-axis model -> .cal -> ATIDAQ's forces = the model's, 1e-6 F.S."""
    model = six_linear if frame is None else replace(
        six_linear, settings=replace(six_linear.settings, frame=frame))
    path = tmp_path / "m.json"
    save_model(model, path)
    model = load_model(path)
    invoke(["export", path, "-o", tmp_path / "s.cal"])
    ref = Atidaq(tmp_path / "s.cal")
    assert ref.force == "N" and ref.torque == "N-m" and ref.max == [100, 100, 200, 5, 5, 5]
    rng = np.random.default_rng(11)
    u = random_outputs(model, rng)
    zero = rng.normal(0, 0.01, 6)
    ref.bias(list(zero))
    expected = decouple(model, u)  # rotated into the frame, as apply writes them
    got = np.array([ref.convert(list(row + zero)) for row in u])
    fs = np.asarray(model.settings.full_scale)
    assert np.all(np.abs(got - expected) <= 1e-6 * fs)


def test_millivolts_are_converted_to_volts(six_linear, tmp_path):
    """A model in mV: ATIDAQ reads volts, so the matrix is scaled, and said."""
    units = replace(six_linear.settings.units, output="mV")
    model = replace(six_linear, settings=replace(six_linear.settings, units=units),
                    matrix=six_linear.matrix / 1000.0)
    path = tmp_path / "mv.json"
    save_model(model, path)
    r = invoke(["export", path, "-o", tmp_path / "s.cal"])
    assert "converted from mV to V" in r.stdout
    ref = Atidaq(tmp_path / "s.cal")
    u_mv = random_outputs(model, np.random.default_rng(2), 50)
    got = np.array([ref.convert([*(row / 1000.0), 0.0]) for row in u_mv])
    assert np.abs(got - u_mv @ model.matrix.T).max() <= 1e-9 * 200


def test_nonlinear_model_refused_unless_linear_part(six_linear, tmp_path):
    svr = replace(six_linear, method="svr")
    path = tmp_path / "svr.json"
    save_model(svr, path)
    out = tmp_path / "s.cal"
    r = invoke(["export", path, "-o", out], code=2)
    assert "--linear-part" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not out.exists()
    r = invoke(["export", path, "-o", out, "--linear-part", "--json"])
    import json

    doc = json.loads(r.stdout)
    ref = Atidaq(out)
    # the omega matrix: f_a = u_a / k_a (eq. 2 inverted), nothing else
    assert np.allclose(ref.working, np.diag(1.0 / svr.k), rtol=1e-15, atol=0)
    # what is lost, re-derived on the model's own calibration points: the zero-corrected
    # sweeps, decoupled by the model (eq. 11) and by omega alone
    settings = load_config(SIX / "sensor.yaml")
    calib = load_calibration(SIX / "calibration", settings)
    u = calib.voltages.astype(float)
    on_calib = 100 * np.abs(svr.decouple(u, rotate=False, exact=True) - u / svr.k).max(axis=0) \
        / np.asarray(settings.full_scale)
    lost = np.array([doc["lost_pct"][a] for a in svr.layout.labels])
    # the figure is the chi the omega matrix leaves out, over the same span: the same to
    # within the calibration's noise and the chi's second-order terms
    assert np.all(lost > 0.5 * on_calib) and np.all(lost < 2.0 * on_calib), (lost, on_calib)


def test_bad_options_for_a_cal(six_linear, tmp_path):
    path = tmp_path / "m.json"
    save_model(six_linear, path)
    r = invoke(["export", path, "-o", tmp_path / "s.cal", "--precision", "float"], code=2)
    assert "for a C header" in r.stderr and not (tmp_path / "s.cal").exists()
    r = invoke(["export", path, "-o", tmp_path / "d.h", "--linear-part"], code=2)
    assert "for a .cal output only" in r.stderr


def test_three_axis_model_refused(tmp_path, sample_model):
    r = invoke(["export", sample_model, "-o", tmp_path / "s.cal", "--linear-part"], code=2)
    assert "six axes" in r.stderr and not (tmp_path / "s.cal").exists()


@needs_cc
def test_c_header_of_an_imported_matrix(tmp_path):
    """export to C: the header's forces are the imported model's (f = W u)."""
    model = import_cal(FIXTURES / "FT_nano_like.cal")
    run, text = build(model, tmp_path)
    # ATI's matrix, said so: it was called the model's least-squares matrix, and C (the
    # identity here) named where W, the projection, holds it
    assert "Decoupling by the factory calibration matrix W (imported from an ATI" in text
    assert "least-squares" not in text
    u = random_outputs(model, np.random.default_rng(4), 2000)
    f_c, status = run(u)
    f_py = decouple(model, u)
    assert np.abs(f_c - f_py).max() <= 1e-12 * max(model.settings.full_scale)
    ref = Atidaq(FIXTURES / "FT_nano_like.cal")
    assert np.abs(f_c[:5] - np.array([ref.convert([*row, 0.0]) for row in u[:5]])).max() \
        <= 1e-9 * 250


@needs_cc
def test_export_of_an_imported_matrix_calls_it_the_factorys(tmp_path):
    invoke(["import", FIXTURES / "FT_nano_like.cal", "-o", tmp_path / "f.json"])
    r = invoke(["export", tmp_path / "f.json", "-o", tmp_path / "f.h"])
    assert "the factory calibration matrix f = W u" in r.stdout and "least-squares" not in r.stdout


@needs_cc
def test_c_header_of_a_temperature_compensated_matrix(tmp_path):
    """export to C of a .cal with BiasSlope/GainSlope: the temperature step of the plan is
    in the header (the thermistor is its input u[NumGages]), checked against the
    independent ATIDAQ implementation (no bias: ATIDAQ's convert before any Bias); a
    header that left the step out would miss by the slopes' effect, checked to be far
    above the tolerance."""
    model = import_cal(FIXTURES / "FT_tc.cal")
    run, text = build(model, tmp_path)
    assert "Temperature: u holds the temperature" in text
    ref = Atidaq(FIXTURES / "FT_tc.cal")
    rng = np.random.default_rng(5)
    g = random_outputs(model, rng, 300)[:, :-1]
    t0 = model.temperature.t0
    t = t0 + rng.uniform(-0.3, 0.3, len(g)) * max(abs(t0), 1.0)
    u = np.column_stack([g, t])
    f_c, _ = run(u)
    want = np.array([ref.convert(list(row)) for row in u])
    fs = max(model.settings.full_scale)
    assert np.abs(f_c - want).max() <= 1e-9 * fs
    without = np.column_stack([g, np.full(len(g), t0)])
    assert np.abs(np.array([ref.convert(list(r)) for r in without]) - want).max() > 1e3 * 1e-9 * fs
    f_py = decouple(model, u, temperature=u[:, -1])
    assert np.abs(f_c - f_py).max() <= 1e-12 * fs




def test_fitted_temperature_terms_read_back_in_atidaq(six_linear, tmp_path):
    """A linear six-axis model with fitted temperature terms (degC) -> .cal -> ATIDAQ, its
    thermistor channel fed the temperature in degC: the forces of the outputs at T0.  The
    raw readings are made in ATI's form from drawn b, g (u = (1 + g dT) u0 + b dT), so
    ATIDAQ's correction must undo them exactly (1e-6 F.S.)."""
    from fsdecouple.core.temperature import TemperatureTerms

    rng = np.random.default_rng(31)
    b, g = rng.normal(0, 1e-3, 6), rng.normal(0, 1.5e-4, 6)  # [V/K], [1/K]
    t0 = 25.0
    model = replace(six_linear, temperature=TemperatureTerms(6, t0, b, g, "degC", (15.0, 35.0)))
    path = tmp_path / "m.json"
    save_model(model, path)
    model = load_model(path)
    r = invoke(["export", path, "-o", tmp_path / "s.cal"])
    assert "degC" in r.stdout + r.stderr
    ref = Atidaq(tmp_path / "s.cal")
    assert ref.tc and ref.n == 6 and ref.therm == t0

    def raw(u0, t):
        return (1 + g * (t - t0)) * u0 + b * (t - t0)

    u = random_outputs(model, rng, rows=200)
    zero, t_bias = rng.normal(0, 0.01, 6), 18.0
    ref.bias([*raw(zero, t_bias), t_bias])
    t = rng.uniform(10.0, 40.0, len(u))
    got = np.array([ref.convert([*raw(row + zero, ti), ti]) for row, ti in zip(u, t, strict=True)])
    expected = decouple(replace(model, temperature=None), u)  # at T0, zero removed
    fs = np.asarray(model.settings.full_scale)
    assert np.all(np.abs(got - expected) <= 1e-6 * fs), np.abs(got - expected).max(axis=0) / fs
    # and the slopes read back as the model's terms
    back = import_cal(tmp_path / "s.cal")
    assert np.allclose(back.temperature.b[:6], b, rtol=1e-15, atol=0)
    assert np.allclose(back.temperature.g[:6], g, rtol=1e-15, atol=0)
