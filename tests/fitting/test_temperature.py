"""Temperature in a calibration and in use (issue 31): the drifting sensor of
``simulate --temperature`` (sim/thermal.py) calibrated at 15, 25 and 35 degC and
applied to a log drifting through 10-40 degC after a tare at 25 degC.

The floors come from the simulator's truth: the log decoupled with the true coupling
(``SimulatedSensor.solve``) after undoing the true linear temperature terms, tared as
apply tares it.  What is left in the floor is the noise and the quadratic drift no
linear form captures; a fitted model may add its fit's own error, within the issue's
limits (1.4x the floor for the worst axis, 1.5x for the error due to temperature alone)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from conftest import FAST_SVR, invoke

from fsdecouple.sim.thermal import ThermalSensor, thermal_log

FS = np.array([100.0, 100.0, 150.0])
# Every test here reads the module's simulated drifting sensor, fitted with its temperature
# terms and applied to two logs: ~6 s of CPU before the first test, beyond the not-slow
# run's budget (issue 30: a minute), so the whole file runs in the full suite.
pytestmark = pytest.mark.slow
TARE = 200


def rms(e: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(e ** 2, axis=0)) / FS


def _fast(drifting, tmp_path):
    """The drifting sensor's config at Table 2's solver tolerance: for fits whose point is
    the temperature terms (fitted before and apart from the SVRs) or a note."""
    cfg = tmp_path / "fast.yaml"
    cfg.write_text((drifting / "sensor.yaml").read_text() + FAST_SVR)
    return cfg


@pytest.fixture(scope="module")
def drifting(tmp_path_factory):
    """simulate --temperature, fit, and apply to the drifting log and its twin at 25 degC."""
    d = tmp_path_factory.mktemp("thermal")
    invoke(["simulate", d, "--temperature", "--seed", "3"])
    cfg = d / "sensor.yaml"
    invoke(["fit", d / "calibration", "-o", d / "model.json", "-c", cfg, "--no-verdict"])
    for name in ("task_voltages", "task_voltages_25C"):
        invoke(["apply", d / "model.json", d / f"{name}.csv", "-o", d / f"{name}_out.csv",
                "-c", cfg, "--tare", TARE])
    return d


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_drifting_log_within_the_floor(drifting):
    sensor = ThermalSensor(seed=3)
    log, twin, f, t = thermal_log(sensor, seed=3)
    # the files hold what the simulator made (7 decimals of a volt)
    written = pd.read_csv(drifting / "task_voltages.csv")
    assert np.abs(written[["ux", "uy", "uz"]].to_numpy() - log).max() < 1e-7
    out = pd.read_csv(drifting / "task_voltages_out.csv")
    out25 = pd.read_csv(drifting / "task_voltages_25C_out.csv")
    fit, fit25 = out[["fx", "fy", "fz"]].to_numpy(), out25[["fx", "fy", "fz"]].to_numpy()
    floor = sensor.floor(log, t, TARE)
    floor25 = sensor.floor(twin, np.full(len(t), 25.0), TARE)
    # worst axis against the floor's worst axis
    assert rms(fit - f).max() <= 1.4 * rms(floor - f).max(), (rms(fit - f), rms(floor - f))
    # the error due to temperature alone: the log against its twin held at 25 degC
    alone, alone_floor = rms(fit - fit25).max(), rms(floor - floor25).max()
    assert alone <= 1.5 * alone_floor, (alone, alone_floor)
    # and it takes the gain terms to get there: the offset terms alone leave far more
    model = json.loads((drifting / "model.json").read_text())
    assert max(abs(v) for v in model["temperature"]["g"].values()) > 5e-5
    # rows beyond the calibrated temperatures (10-15 and 35-40 degC) are extrapolated
    span = model["temperature"]["span"]
    beyond = (t < span[0]) | (t > span[1])
    assert beyond.any() and (out["status"].to_numpy()[beyond] == "extrapolated").all()


def test_fitted_terms_near_the_truth(drifting):
    """b_i and g_i in the model file, within 4 of their own standard uncertainties of the
    simulator's truth (and those uncertainties small: 3 % of b, 15 % of g)."""
    truth = ThermalSensor(seed=3).truth
    terms = json.loads((drifting / "model.json").read_text())["temperature"]
    assert terms["t0"] == 25.0 and terms["unit"] == "degC"
    for i, o in enumerate(("ux", "uy", "uz")):
        b, sb = terms["b"][o], terms["b_sigma"][o]
        g, sg = terms["g"][o], terms["g_sigma"][o]
        # ATI's form with T0 = 25: the truth's b and g, as simulated
        assert abs(b - truth["b"][i]) <= 4 * sb and sb <= 0.03 * abs(truth["b"][i]), (o, b, sb)
        assert abs(g - truth["g"][i]) <= 4 * sg and sg <= 0.15 * abs(truth["g"][i]), (o, g, sg)


def test_fit_prints_the_terms_and_the_heldout_figure(drifting):
    model = json.loads((drifting / "model.json").read_text())
    held = model["report"]["temperature"]["heldout"]
    assert [round(h["temperature"]) for h in held] == [15, 25, 35]
    for h in held:  # away from T0 the compensation is worth it; at T0 it changes little
        if abs(h["temperature"] - 25) > 5:
            assert h["worst_rms_pct_fs_with"] < 0.8 * h["worst_rms_pct_fs_without"], h
    r = invoke(["show", drifting / "model.json"])
    assert "Temperature terms" in r.stdout and "ppm/K" in r.stdout and "±" in r.stdout


def test_a_log_without_the_column_is_refused_unless_temperature_given(drifting, tmp_path):
    log = pd.read_csv(drifting / "task_voltages_25C.csv").drop(columns="temperature")
    log.to_csv(tmp_path / "log.csv", index=False)
    r = invoke(["apply", drifting / "model.json", tmp_path / "log.csv", "-o", tmp_path / "o.csv",
                "-c", drifting / "sensor.yaml"], code=2)
    assert "temperature" in r.stderr and "--temperature" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "o.csv").exists()
    invoke(["apply", drifting / "model.json", tmp_path / "log.csv", "-o", tmp_path / "o.csv",
            "-c", drifting / "sensor.yaml", "--tare", TARE, "--temperature", "25"])
    # held at 25 degC throughout, as the twin is: the same forces
    a = pd.read_csv(tmp_path / "o.csv")[["fx", "fy", "fz"]].to_numpy()
    b = pd.read_csv(drifting / "task_voltages_25C_out.csv")[["fx", "fy", "fz"]].to_numpy()
    assert np.abs(a - b).max() <= 1e-6 * FS.max()


def test_kelvin_and_fahrenheit_read_as_celsius(drifting, tmp_path):
    from fsdecouple import load_calibration, load_config

    cal = tmp_path / "cal"
    cal.mkdir()
    for p in sorted((drifting / "calibration").glob("rep*.csv"))[:3]:
        df = pd.read_csv(p)
        df["temperature"] = df["temperature"] * 9 / 5 + 32
        df.rename(columns={"temperature": "T [°F]"}).to_csv(cal / p.name, index=False)
    (tmp_path / "f.yaml").write_text("columns: {temperature: 'T [°F]'}\nunits: {temperature: degF}\n"
                                     "min_repetitions: 3\n")
    got = load_calibration(cal, load_config(tmp_path / "f.yaml")).points["temperature"]
    want = pd.concat([pd.read_csv(p)["temperature"]
                      for p in sorted((drifting / "calibration").glob("rep*.csv"))[:3]])
    assert np.abs(got.to_numpy() - want.to_numpy()).max() < 1e-9
    (tmp_path / "k.yaml").write_text("columns: {temperature: 'T [°F]'}\nunits: {temperature: K}\n"
                                     "min_repetitions: 3\n")
    got = load_calibration(cal, load_config(tmp_path / "k.yaml")).points["temperature"]
    assert np.abs(got.to_numpy() - (want.to_numpy() * 9 / 5 + 32 - 273.15)).max() < 1e-9


def test_temperature_column_holding_text(drifting, tmp_path):
    cal = tmp_path / "cal"
    cal.mkdir()
    for p in sorted((drifting / "calibration").glob("rep*.csv")):
        (cal / p.name).write_text(p.read_text())
    lines = (cal / "rep2.csv").read_text().splitlines()
    cells = lines[6].split(",")
    cells[-1] = "warm"
    lines[6] = ",".join(cells)
    (cal / "rep2.csv").write_text("\n".join(lines) + "\n")
    r = invoke(["fit", cal, "-o", tmp_path / "m.json", "-c", drifting / "sensor.yaml"], code=2)
    assert "rep2.csv" in r.stderr and "row 7" in r.stderr and "temperature" in r.stderr
    assert "warm" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "m.json").exists()


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_a_narrow_span_fits_no_terms(drifting, tmp_path):
    """Temperatures within 5 K: no terms (the model file has none), and fit says why."""
    cal = tmp_path / "cal"
    cal.mkdir()
    for p in sorted((drifting / "calibration").glob("rep*.csv")):
        df = pd.read_csv(p)
        df["temperature"] = 25.0 + (df["temperature"] - 25.0) / 10  # 24 .. 26 degC
        df.to_csv(cal / p.name, index=False)
    r = invoke(["fit", cal, "-o", tmp_path / "m.json", "-c", _fast(drifting, tmp_path),
                "--no-verdict"])
    assert (r.stdout + r.stderr).count("less than 5 K") == 1  # said once (it was twice)
    doc = json.loads((tmp_path / "m.json").read_text())
    assert "temperature" not in doc
    assert sum("less than 5 K" in w for w in doc["report"]["warnings"]) == 1


@pytest.mark.parametrize("header,unit", [("temp", "degC"), ("temperature", "degC"),
                                         ("T [°C]", "degC"), ("temp_C", "degC"),
                                         ("thermistor", "degC"), ("Temp [K]", "K")])
def test_init_recognises_a_temperature_column(tmp_path, header, unit):
    import yaml

    data = tmp_path / "cal.csv"
    data.write_text(f"axis,fx,fy,fz,ux,uy,uz,{header}\n" + "".join(
        f"{a},{v if a == 'x' else 0},{v if a == 'y' else 0},{v if a == 'z' else 0},"
        f"{v / 75 if a == 'x' else 0.001},{v / 78 if a == 'y' else 0.001},"
        f"{v / 125 if a == 'z' else 0.001},25\n" for a in "xyz" for v in (0, 50, 100)),
        encoding="utf-8")
    invoke(["init", data, "-o", tmp_path / "c.yaml"])
    doc = yaml.safe_load((tmp_path / "c.yaml").read_text(encoding="utf-8"))
    assert doc["columns"]["temperature"] == header and doc["units"]["temperature"] == unit


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_report_certificate_and_compare_show_the_terms(drifting, tmp_path, unrendered):
    # the report's figures built, not rasterised (conftest's unrendered): its text is the point
    invoke(["report", drifting / "model.json", "-o", tmp_path / "r.html"])
    html = (tmp_path / "r.html").read_text(encoding="utf-8")
    assert 'id="temperature"' in html and "ppm/K" in html
    invoke(["validate", drifting / "model.json", drifting / "calibration", "-c",
            drifting / "sensor.yaml", "--json", "-o", tmp_path / "v.json"])
    doc = json.loads((tmp_path / "v.json").read_text())
    terms = json.loads((drifting / "model.json").read_text())["temperature"]
    assert doc["temperature"]["b"] == terms["b"]
    r = invoke(["compare", drifting / "model.json", drifting / "model.json", "--json"])
    t = json.loads(r.stdout)["temperature"]
    assert t["b_change"] == {"ux": 0.0, "uy": 0.0, "uz": 0.0}


def test_decouple_frame_reads_the_temperature_as_apply_does(drifting):
    """The Python API on a DataFrame: the same forces and statuses as apply (to its 8
    written decimals) on the drifting log."""
    from fsdecouple import decouple_frame, load_model

    model = load_model(drifting / "model.json")
    got = decouple_frame(model, pd.read_csv(drifting / "task_voltages.csv"), tare=TARE)
    out = pd.read_csv(drifting / "task_voltages_out.csv")
    assert np.abs(got[["fx", "fy", "fz"]].to_numpy() - out[["fx", "fy", "fz"]].to_numpy()).max() <= 1e-8
    assert (got["status"].to_numpy() == out["status"].to_numpy()).all()


def test_apply_tells_the_zeros_temperature_in_its_own_unit(drifting, tmp_path):
    """The tare's temperature is a reading in degC, not a zero removed in volts (it was
    printed as 'zero removed [V]: ... temperature=+25.0')."""
    r = invoke(["apply", drifting / "model.json", drifting / "task_voltages.csv", "-o",
                tmp_path / "out.csv", "-c", drifting / "sensor.yaml", "--tare", TARE])
    line = next(x for x in r.stdout.splitlines() if x.startswith("zero removed"))
    mean = pd.read_csv(drifting / "task_voltages.csv")["temperature"][:TARE].mean()
    assert line.startswith("zero removed [V]: ux=") and "temperature=" not in line
    assert line.endswith(f"; read at {mean:.6g} degC (temperature)"), line


def test_validate_needs_the_temperature_column(drifting, tmp_path):
    (tmp_path / "plain.yaml").write_text("sensor: plain\n")
    cal = tmp_path / "cal"
    cal.mkdir()
    for p in sorted((drifting / "calibration").glob("rep*.csv")):
        pd.read_csv(p).drop(columns="temperature").to_csv(cal / p.name, index=False)
    r = invoke(["validate", drifting / "model.json", cal, "-c", tmp_path / "plain.yaml"], code=2)
    assert "no temperature column mapped" in r.stderr and len(r.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("extra", [["--components", "6"], ["--layout", "lab"], ["--hysteresis", "0.01"],
                                   ["--repetitions", "2"]])
def test_simulate_temperature_refuses_what_it_cannot_honour(tmp_path, extra):
    r = invoke(["simulate", tmp_path / "s", "--temperature", *extra], code=2)
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "s").exists()


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_offsets_jumping_between_sweeps_keep_each_sweeps_zero(drifting, tmp_path):
    """Sweeps whose zero jumps by 0.02 V (40x the noise) at random: the fit no longer zeroes
    by its common z (offset_t0 None), and b's uncertainty grows to cover the jumps."""
    from fsdecouple import load_calibration, load_config
    from fsdecouple.fitting.temperature import fit_terms
    from fsdecouple.fitting.threads import single_threaded_libraries

    settings = load_config(drifting / "sensor.yaml")
    rng = np.random.default_rng(1)
    cal = tmp_path / "cal"
    cal.mkdir()
    for p in sorted((drifting / "calibration").glob("rep*.csv")):
        df = pd.read_csv(p)
        for axis in "xyz":
            rows = df["axis"] == axis
            df.loc[rows, ["ux", "uy", "uz"]] += rng.uniform(-0.02, 0.02, 3)
        df.to_csv(cal / p.name, index=False)
    # the terms as compensate fits them (fit_terms, on one BLAS thread as there; compensate
    # adds its held-out figure, three more fits of the terms, which the zero does not use)
    with single_threaded_libraries():
        steady = fit_terms(load_calibration(drifting / "calibration", settings), settings)
        jumpy = fit_terms(load_calibration(cal, settings), settings)
    assert steady.offset_t0 is not None and jumpy.offset_t0 is None
    assert (jumpy.terms.b_sigma > 3 * steady.terms.b_sigma).all()


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_a_column_named_temperature_needs_no_mapping(drifting, tmp_path):
    """As fx is read from a column named fx: fit and apply without a config read the column
    named 'temperature' (degC), and give the forces the config gives."""
    invoke(["fit", drifting / "calibration", "-o", tmp_path / "m.json", "--no-verdict"])
    doc = json.loads((tmp_path / "m.json").read_text())
    mapped = json.loads((drifting / "model.json").read_text())
    assert doc["temperature"]["b"] == mapped["temperature"]["b"]
    invoke(["apply", tmp_path / "m.json", drifting / "task_voltages.csv", "-o", tmp_path / "o.csv",
            "--tare", TARE])
    a = pd.read_csv(tmp_path / "o.csv")[["fx", "fy", "fz"]].to_numpy()
    b = pd.read_csv(drifting / "task_voltages_out.csv")[["fx", "fy", "fz"]].to_numpy()
    assert np.abs(a - b).max() <= 1e-6 * FS.max()


def _soak(truth: dict, n: int = 300, seed: int = 0) -> pd.DataFrame:
    """A soak from 10 to 40 degC, every load zero: the simulator's true offsets (ATI's form
    about its t0, truth.json) plus noise of the sensor's own size (sim.sensor's noise)."""
    from fsdecouple.sim.simulate import SimulatedSensor

    rng = np.random.default_rng(seed)
    t = np.linspace(10.0, 40.0, n)
    dt = t - truth["t0"]
    outs = ("ux", "uy", "uz")
    sigma = SimulatedSensor().noise
    u = {o: (1 + truth["g"][o] * dt) * truth["z"][o] + truth["b"][o] * dt
         + rng.normal(0.0, sigma, n) for o in outs}
    return pd.DataFrame({"axis": "", "fx": 0.0, "fy": 0.0, "fz": 0.0, **u,
                         "temperature": t + rng.normal(0.0, 0.02, n)})


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_a_soak_file_pins_the_offset_drift(drifting, tmp_path):
    """A file of zero-load rows over 10-40 degC beside the repetitions: accepted with a note,
    not a repetition, and b_i's uncertainty shrinks while b_i stays by the truth."""
    truth = json.loads((drifting / "truth.json").read_text())
    cal = tmp_path / "cal"
    cal.mkdir()
    for p in sorted((drifting / "calibration").glob("rep*.csv")):
        (cal / p.name).write_text(p.read_text())
    _soak(truth).drop(columns="axis").to_csv(cal / "soak.csv", index=False, float_format="%.7f")
    r = invoke(["fit", cal, "-o", tmp_path / "m.json", "-c", _fast(drifting, tmp_path),
                "--no-verdict"])
    assert "soak.csv" in r.stdout + r.stderr and "b_i only" in r.stdout + r.stderr
    doc = json.loads((tmp_path / "m.json").read_text())
    before = json.loads((drifting / "model.json").read_text())["temperature"]
    after = doc["temperature"]
    for o in ("ux", "uy", "uz"):
        assert after["b_sigma"][o] < 0.8 * before["b_sigma"][o], (o, after, before)
        assert abs(after["b"][o] - truth["b"][o]) <= 4 * after["b_sigma"][o], (o, after)
    from fsdecouple import load_calibration, load_config

    calib = load_calibration(cal, load_config(drifting / "sensor.yaml"))
    assert calib.repetitions == [1, 2, 3, 4, 5, 6] and len(calib.soak) == 300


def test_a_soak_without_temperature_is_refused(drifting, tmp_path):
    truth = json.loads((drifting / "truth.json").read_text())
    cal = tmp_path / "cal"
    cal.mkdir()
    for p in sorted((drifting / "calibration").glob("rep*.csv")):
        pd.read_csv(p).drop(columns="temperature").to_csv(cal / p.name, index=False)
    _soak(truth).drop(columns=["axis", "temperature"]).to_csv(cal / "soak.csv", index=False)
    r = invoke(["fit", cal, "-o", tmp_path / "m.json"], code=2)
    assert "soak.csv" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "m.json").exists()
    # a soak spanning less than the fit's minimum: refused too
    for p in sorted((drifting / "calibration").glob("rep*.csv")):
        (cal / p.name).write_text(p.read_text())
    narrow = _soak(truth).drop(columns="axis")
    narrow["temperature"] = 25.0
    narrow.to_csv(cal / "soak.csv", index=False)
    r = invoke(["fit", cal, "-o", tmp_path / "m.json", "-c", drifting / "sensor.yaml"], code=2)
    assert "soak.csv" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
