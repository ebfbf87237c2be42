"""N-component sensors: the layout from the config, end to end on a simulated six-axis sensor."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from conftest import ROOT, SAMPLE, assert_decouples_by_its_own_numbers, assert_refit_close, invoke

from fsdecouple import load_calibration, load_config, load_model
from fsdecouple.axes import AXES, CHI_NAMES, DEFAULT, FORCE_COLUMNS, VOLTAGE_COLUMNS, Layout
from fsdecouple.config import settings_from_dict
from fsdecouple.core.modelfile import model_from_dict, model_to_dict
from fsdecouple.data.calibration import from_table
from fsdecouple.errors import ConfigError, InputError
from fsdecouple.fitting.fit import fit
from fsdecouple.fitting.linear import fit_calibration_matrix
from fsdecouple.sim.six_axis import (
    COMPONENTS,
    OUTPUTS,
    TARE_ROWS,
    simulate_calibration,
    six_axis_sensor,
    write_six_axis,
)

SIX = SAMPLE / "six_axis"
CONFIG = ROOT / "configs" / "six-axis.yaml"


@pytest.fixture(scope="module")
def six_settings():
    return load_config(CONFIG)


@pytest.fixture(scope="module")
def six_calib(six_settings):
    return load_calibration(SIX / "calibration", six_settings)


@pytest.fixture(scope="module")
def six_model(six_calib, six_settings):
    return fit(six_calib, six_settings)


def _table(sensor, settings, seed=0, repetitions=6):
    t = simulate_calibration(sensor, repetitions, seed)
    t["file"], t["row"] = "sim.csv", np.arange(len(t)) + 2
    return t[["repetition", "axis", "file", "row", *settings.layout.loads, *settings.layout.outputs]]


# --- the layout --------------------------------------------------------------------

def test_the_default_layout_is_todays_names():
    assert DEFAULT.labels == AXES == ("x", "y", "z")
    assert DEFAULT.loads == FORCE_COLUMNS and DEFAULT.outputs == VOLTAGE_COLUMNS
    assert DEFAULT.chi_names == CHI_NAMES == ("xy", "xz", "yx", "yz", "zx", "zy")
    # a config naming today's columns is today's sensor, labels and chi names included
    assert Layout.named(("fx", "fy", "fz"), ("ux", "uy", "uz")) is DEFAULT
    assert load_config().layout is DEFAULT


def test_named_components_label_sweeps_and_chi():
    layout = Layout.named(COMPONENTS, OUTPUTS)
    assert layout.n == 6 and len(layout.chi_names) == 30
    assert layout.chi_names[:5] == ("fx:fy", "fx:fz", "fx:mx", "fx:my", "fx:mz")
    for name, pair in zip(layout.chi_names, layout.pairs, strict=True):
        assert layout.pair(name) == pair  # every name reads back as its own pair


# --- the config ----------------------------------------------------------------------

def test_config_reads_components_outputs_full_scale_and_units(six_settings):
    s = six_settings
    assert s.layout.loads == COMPONENTS and s.layout.outputs == OUTPUTS
    assert s.full_scale == (100.0, 100.0, 200.0, 5.0, 5.0, 5.0)
    assert [s.units.load_of(a) for a in range(6)] == ["N"] * 3 + ["N·m"] * 3
    assert s.units.output_of(5) == "V"
    assert s.columns["u4"] == "u4" and s.scale["mz"] == 1.0
    assert s.zero_method == "fit" and load_config().zero_method == "rows"


BASE = {"components": ["fx", "mx"], "outputs": ["a", "b"], "full_scale": {"fx": 1, "mx": 2}}


@pytest.mark.parametrize(("change", "match"), [
    ({"outputs": ["a", "a"]}, "'a' is listed twice"),
    ({"outputs": ["a"]}, "1 names for 2 components"),
    ({"outputs": None}, "components needs outputs"),
    ({"components": ["fx", "f:x"]}, "is not a name"),
    ({"full_scale": {"fx": 1}}, "missing axis mx"),
    ({"full_scale": None}, "needs the full scale"),
    ({"units": {"load": {"fx": "N"}}}, "no unit for mx"),
    ({"units": {"load": {"fx": "N", "mx": "furlong"}}}, "unknown unit 'furlong'"),
    ({"columns": {"a": "ch1", "b": "ch1"}}, r"same file column \('ch1': a and b\)"),
    ({"outputs": ["fx", "b"]}, "names a component and an output"),
])
def test_bad_layouts_are_refused_with_one_line(change, match):
    raw = {**BASE, **change}
    raw = {k: v for k, v in raw.items() if v is not None}
    with pytest.raises(ConfigError, match=match):
        settings_from_dict(raw, "s.yaml")


def test_one_unit_for_all_and_per_column_units_agree():
    one = settings_from_dict({**BASE, "units": {"load": "N"}})
    per = settings_from_dict({**BASE, "units": {"load": {"fx": "N", "mx": "N"}}})
    assert one.units == per.units  # one unit however it is spelt: models and logs agree


# --- ingest, fit, model file, apply --------------------------------------------------

def test_ingest_reads_component_labels(six_calib):
    assert six_calib.layout.loads == COMPONENTS
    assert set(six_calib.points["axis"]) == set(COMPONENTS)
    assert six_calib.forces.shape[1] == six_calib.voltages.shape[1] == 6
    assert len(six_calib.offsets) == 36  # six sweeps a repetition


def test_a_combined_load_row_joins_the_sweep_of_its_largest_relative_load(six_settings):
    """A force at a lever arm (fy and mx at once) is fitted, not refused (issue 22): the row
    joins the sweep whose load is the larger fraction of its full scale."""
    t = _table(six_axis_sensor(0), six_settings)
    i = int(np.flatnonzero((t["axis"] == "fy") & (t["fy"] != 0))[3])
    t["axis"] = ""  # inferred from the loads, as in a rig file without an axis column
    fs = dict(zip(six_settings.layout.loads, six_settings.full_scale, strict=True))
    t.loc[i, "mx"] = 0.9 * fs["mx"] * abs(t.loc[i, "fy"]) / fs["fy"]  # just below fy's fraction
    cs = from_table(t, six_settings)
    pts = cs.points
    row = pts[(pts["row"] == t.loc[i, "row"]) & (pts["repetition"] == t.loc[i, "repetition"])]
    assert list(row["axis"]) == ["fy"]


def test_a_component_without_a_sweep_is_refused(six_settings):
    t = _table(six_axis_sensor(0), six_settings)
    t = t[~((t["repetition"] == 2) & (t["axis"] == "my"))]
    with pytest.raises(InputError, match="repetition 2 has no my sweep; every repetition must "
                                         "calibrate all 6 components"):
        from_table(t, six_settings)


def test_fit_recovers_the_simulated_slopes(six_model):
    truth = six_axis_sensor(0)
    # 126 points a slope at 0.5 mV noise on ~1.5 V: k to about 1e-4 relative (worst
    # of sensors of seeds 0-23: mean 0.9e-4, max 2.2e-4)
    np.testing.assert_allclose(six_model.k, truth.k, rtol=1e-3)
    assert len(six_model.chi) == 30
    assert six_model.chi["my:fz"].output_axis == 4 and six_model.chi["my:fz"].input_axis == 2


def test_fitted_chi_follow_the_true_coupling(six_model):
    truth = six_axis_sensor(0)
    for name, c in six_model.chi.items():
        b = c.input_axis
        f = np.linspace(-0.6, 0.6, 50) * truth.full_scale[b]
        # in the b sweeps u_b = k_b f_b exactly (eq. 2), so chi_ab(k_b f) = phi_ab(f) (eq. 4);
        # 8 sigma of the 0.5 mV noise bounds an SVR fit to 126 noisy points (the worst
        # chi of sensors of seeds 0-23: mean 1.47, max 1.80 sigma)
        assert np.abs(c(truth.k[b] * f) - truth.phi(name, f)).max() < 8 * truth.noise, name


def test_fitted_offsets_are_closer_to_the_truth_than_the_zero_rows(six_settings):
    """zero: fit rests each offset on all the sweep's points (zero.fitted_offsets)."""
    sensor = replace(six_axis_sensor(3), noise=0.002)
    t = _table(sensor, six_settings, seed=3)
    clean = _table(replace(sensor, noise=0.0), six_settings, seed=3)
    # the same seed draws the same offsets; noise-free zero rows give the true offsets
    true = from_table(clean, replace(six_settings, zero="rows")).offsets
    err = {}
    for method in ("rows", "fit"):
        got = from_table(t, replace(six_settings, zero=method)).offsets
        err[method] = np.sqrt(np.mean((got[list(OUTPUTS)].to_numpy()
                                       - true[list(OUTPUTS)].to_numpy()) ** 2))
    # over seeds 0-23: rows / sigma mean 1.01, sd 0.056, range 0.87-1.11; fit / rows
    # mean 0.26, sd 0.021, max 0.31: both limits beyond the max x 1.25
    assert err["rows"] == pytest.approx(sensor.noise, rel=0.2)  # one zero row: sigma
    assert err["fit"] < 0.6 * err["rows"]


def test_model_file_round_trip(six_model):
    doc = model_to_dict(six_model)
    assert doc["format_version"] == 3
    assert doc["settings"]["components"] == list(COMPONENTS)
    assert doc["chi"]["fx:my"]["output_axis"] == "fx" and doc["chi"]["fx:my"]["input_axis"] == "my"
    back = model_from_dict(json.loads(json.dumps(doc)))
    assert back.layout == six_model.layout
    u = np.random.default_rng(0).uniform(-1, 1, (50, 6))
    np.testing.assert_array_equal(back.decouple(u), six_model.decouple(u))


def test_decoupler_takes_six_outputs(six_model):
    u = np.random.default_rng(1).uniform(-1, 1, (20, 6))
    one = six_model.decoupler()
    got = np.array([one(*row) for row in u])
    np.testing.assert_allclose(got, six_model.decouple(u), rtol=0, atol=1e-12)


# six_model_file: conftest's, the session's `fsdecouple fit` of the six-axis sample


@pytest.mark.slow  # a six-axis fit with its verdict: seconds of CPU; the not-slow run stays under a minute
def test_cli_fit_show_apply(tmp_path, six_model_file):
    model = six_model_file
    shown = invoke(["show", model]).stdout
    assert "chi_mz:my" in shown and "u6" in shown
    out = tmp_path / "f.csv"
    invoke(["apply", model, SIX / "task_voltages.csv", "--tare", TARE_ROWS, "-o", out])
    got = pd.read_csv(out)
    assert list(got.columns) == ["t", *OUTPUTS, *COMPONENTS, "status"]
    u = pd.read_csv(SIX / "task_voltages.csv")[list(OUTPUTS)].to_numpy()
    want = load_model(model).decouple(u - u[:TARE_ROWS].mean(axis=0))
    np.testing.assert_allclose(got[list(COMPONENTS)].to_numpy(), want, rtol=0, atol=1e-6)


def test_a_six_axis_model_on_a_three_column_log(tmp_path, six_model):
    from fsdecouple.core.modelfile import save_model

    path = tmp_path / "m.json"
    save_model(six_model, path)
    err = invoke(["apply", path, SAMPLE / "task_voltages.csv", "-o", tmp_path / "f.csv"], code=2)
    assert "u1" in err.stderr and "Traceback" not in err.stderr
    assert not (tmp_path / "f.csv").exists()


def test_export_uses_the_layouts_outputs(six_model, tmp_path):
    from fsdecouple.export.header import export_header

    out = tmp_path / "d.h"
    export_header(six_model, out, limits={"u6": (-3.0, 3.0)})
    text = out.read_text()
    assert "chi_axes[30][2]" in text and "-3" in text


# --- the accuracy the issue asks for -------------------------------------------------

def _errors(seed, tmp_path):
    """Per-component RMS error of fit + eq. (11), of the true coupling solved exactly
    (the floor) and of the least-squares matrix, on the combined-load log."""
    sensor = six_axis_sensor(seed)
    write_six_axis(tmp_path, seed=seed, sensor=sensor)
    settings = load_config(tmp_path / "sensor.yaml")
    calib = load_calibration(tmp_path / "calibration", settings)
    model = fit(calib, settings)
    u = pd.read_csv(tmp_path / "task_voltages.csv")[list(OUTPUTS)].to_numpy()
    u = u - u[:TARE_ROWS].mean(axis=0)
    f = pd.read_csv(tmp_path / "task_forces.csv")[list(COMPONENTS)].to_numpy()

    def rms(g):
        return np.sqrt(np.mean((g - f) ** 2, axis=0))

    matrix = fit_calibration_matrix(calib.voltages, calib.forces).C
    return rms(model.decouple(u)), rms(sensor.solve(u)), rms(u @ matrix.T)


# The limits come from the scatter over 62 simulated sensors (seeds 1-60, 101, 202;
# _errors as below, default settings), worst component of each seed:
#   fit + eq. (11) / floor:   mean 1.94, sd 0.19, max 2.37 (seed 36; 101: 1.94, 202: 1.79)
#   fit + eq. (11) / linear:  mean 0.28, sd 0.085, max 0.51 (seed 44)
# One seed also moves between machines (libsvm's last bits: 101 was 2.20x on another
# one).  Limits: 3.0x the floor (the max x 1.25 = 2.97; mean + 5.5 sd) and 0.7x the
# least-squares matrix (the max x 1.37).  Both keep their teeth: the matrix itself is
# 10-28x the floor on each seed's worst component, and a fit no better than it is 1.0x.
FLOOR_LIMIT, LINEAR_LIMIT = 3.0, 0.7


@pytest.mark.slow
@pytest.mark.parametrize("seed", [101, 202])
def test_six_axis_accuracy_against_the_floor(seed, tmp_path):
    """The hidden check: unseen sensors, default settings, combined loads vs the true wrench."""
    svr, floor, linear = _errors(seed, tmp_path)
    assert (svr <= FLOOR_LIMIT * floor).all(), svr / floor
    assert (svr <= LINEAR_LIMIT * linear).all(), svr / linear


def test_sample_six_axis_is_the_simulator_output(tmp_path):
    """sample_data/six_axis/ is exactly what `fsdecouple simulate --components 6` writes."""
    invoke(["simulate", tmp_path, "--components", "6"])
    files = sorted(p.relative_to(SIX) for p in SIX.rglob("*") if p.is_file())
    assert len(files) == 9
    for rel in files:
        assert (tmp_path / rel).read_bytes() == (SIX / rel).read_bytes(), rel
    # the config written beside the data is configs/six-axis.yaml but for the name
    assert (SIX / "sensor.yaml").read_text().replace("sim-6axis-seed0", "sim-6axis") \
        == CONFIG.read_text()


GOLDEN_SIX = ROOT / "tests" / "fixtures" / "golden" / "six-axis-v3.json"


def _six_task_outputs():
    u = pd.read_csv(SIX / "task_voltages.csv")[list(OUTPUTS)].to_numpy()
    return u - u[:TARE_ROWS].mean(axis=0)


def test_golden_six_axis_file_loads_and_decouples_by_its_own_numbers():
    """The stored model, not a re-fit: eq. (11) from the file's slopes, support vectors
    and coefficients, to rounding on every machine (conftest.py, EXACT_TOL / TABLE_TOL)."""
    assert_decouples_by_its_own_numbers(GOLDEN_SIX, _six_task_outputs())


def test_a_fresh_six_axis_fit_decouples_like_the_golden_file_within_the_noise(six_model):
    """A re-fit differs from the file by libsvm's last bits grown through the fit (another
    machine: up to 0.089 % F.S.): within REFIT_MAX / REFIT_RMS of full scale (conftest.py)."""
    assert_refit_close(load_model(GOLDEN_SIX), six_model, _six_task_outputs())


# --- the frame transform (wrench.py) -------------------------------------------------

QUARTER_TURN_Z = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]


def test_frame_moves_moments_to_the_reference_origin_hand_worked():
    """R: a quarter turn about z; the sensor's measuring point at r = (0.1, 0, 0) m.

    A sensor wrench F = (10, 0, 0) N, M = (0, 0, 1) N·m is, in the reference
    frame, a force of 10 N along y through (0.1, 0, 0) plus the couple: about the
    reference origin that is F' = (0, 10, 0) N and M' = (0, 0, 1 + 0.1 * 10) N·m.
    """
    s = settings_from_dict({"components": list(COMPONENTS), "outputs": list(OUTPUTS),
                            "full_scale": dict.fromkeys(COMPONENTS, 1),
                            "frame": {"rotation": QUARTER_TURN_Z, "origin": [0.1, 0, 0]}})
    got = s.frame.matrix() @ np.array([10.0, 0, 0, 0, 0, 1.0])
    np.testing.assert_allclose(got, [0, 10, 0, 0, 0, 2.0], rtol=0, atol=1e-12)
    # a moment alone only turns with the frame: a couple is free
    np.testing.assert_allclose(s.frame.matrix() @ np.array([0, 0, 0, 1.0, 0, 0]),
                               [0, 0, 0, 0, 1.0, 0], atol=1e-12)


def test_frame_applies_after_eq_11(six_model):
    from fsdecouple.wrench import Frame

    frame = Frame(tuple(map(tuple, QUARTER_TURN_Z)), (0.05, -0.02, 0.3))
    framed = replace(six_model, settings=replace(six_model.settings, frame=frame))
    u = np.random.default_rng(2).uniform(-1, 1, (40, 6))
    f = six_model.decouple(u)
    force, moment = f[:, :3] @ np.asarray(QUARTER_TURN_Z, float).T, f[:, 3:] @ np.asarray(
        QUARTER_TURN_Z, float).T
    want = np.hstack([force, moment + np.cross(frame.origin, force)])  # M' = R M + r x (R F)
    np.testing.assert_allclose(framed.decouple(u), want, rtol=0, atol=1e-12)
    np.testing.assert_allclose(framed.decouple(u, rotate=False), f, rtol=0, atol=0)
    one = framed.decoupler()
    np.testing.assert_allclose(one(*u[0]), want[0], rtol=0, atol=1e-12)
    back = model_from_dict(json.loads(json.dumps(model_to_dict(framed))))
    assert back.settings.frame == frame


@pytest.mark.parametrize(("raw", "match"), [
    ({"frame": {"origin": [0.1, 0.2]}}, r"origin: expected \[x, y, z\], three numbers, found 2"),
    ({"frame": {"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, -1]]}}, "reflection"),
    ({"frame": {"origin": [0, 0, 0], "offset": 1}}, "unknown key 'offset'"),
    ({"rotation": QUARTER_TURN_Z}, "takes frame"),
])
def test_bad_frames_are_refused(raw, match):
    with pytest.raises(ConfigError, match=match):
        settings_from_dict({"components": list(COMPONENTS), "outputs": list(OUTPUTS),
                            "full_scale": dict.fromkeys(COMPONENTS, 1), **raw})


def test_a_frame_needs_six_components():
    with pytest.raises(ConfigError, match="this one has 3: use rotation"):
        settings_from_dict({"frame": {"origin": [0, 0, 0]}})


# --- gamma for mixed units (metrics.py) ----------------------------------------------

def test_gamma_is_eq_12_as_printed_for_a_three_axis_force_sensor():
    from fsdecouple.core.metrics import interference_errors

    rng = np.random.default_rng(4)
    f = rng.normal(0, 3, (60, 3))
    points = pd.DataFrame({"axis": np.repeat(["x", "y", "z"], 20)})
    fs = (100.0, 100.0, 150.0)  # the paper's unequal full scales
    for units in (None, ("N", "N", "N")):
        got = interference_errors(points, f, fs, DEFAULT, units)
        x, y, z = f[:20], f[20:40], f[40:]
        # eq. (12) written out: gamma_x = (max|f_y(m)| + max|f_z(m)|) / f_x(FS), likewise y, z
        assert got == {
            "x": (np.abs(x[:, 1]).max() + np.abs(x[:, 2]).max()) / 100.0,
            "y": (np.abs(y[:, 0]).max() + np.abs(y[:, 2]).max()) / 100.0,
            "z": (np.abs(z[:, 0]).max() + np.abs(z[:, 1]).max()) / 150.0,
        }


def test_gamma_with_forces_and_moments_is_dimensionless():
    from fsdecouple.core.metrics import interference_error

    rng = np.random.default_rng(5)
    f = rng.normal(0, 1, (30, 6)) * [1, 1, 1, 0.05, 0.05, 0.05]
    fs = np.array([100.0, 100.0, 200.0, 5.0, 5.0, 5.0])
    units = ("N",) * 3 + ("N·m",) * 3
    mm = np.array([1, 1, 1, 1000, 1000, 1000.0])  # the same moments in N·mm
    for a in range(6):
        g = interference_error(f, a, fs, units)
        assert g == pytest.approx(interference_error(f * mm, a, fs * mm, units), rel=1e-12)
        # by hand: shared-unit components over the loaded one's full scale, others over their own
        same = [b for b in range(6) if b != a and units[b] == units[a]]
        other = [b for b in range(6) if units[b] != units[a]]
        want = sum(np.abs(f[:, b]).max() for b in same) / fs[a] + sum(
            np.abs(f[:, b]).max() / fs[b] for b in other)
        assert g == pytest.approx(want, rel=1e-12)
    # eq. (12) as printed would add N·m to N: its value changes with the moment unit
    assert interference_error(f, 0, fs[0]) != pytest.approx(interference_error(f * mm, 0, fs[0]))


# --- cv and validate -----------------------------------------------------------------

GROSS = "MY:2:5:0.2"  # a point of a named component, spelt in capitals


@pytest.fixture(scope="module")
def six_cv(six_calib, six_settings):
    """`fsdecouple cv` of the six-axis sample with its task log and a gross error on my
    (GROSS), as plain JSON data (the cv.json document), once for the module.  The gross
    error's run adds ~0.6 s of CPU to the cv's 2.2 s and leaves its clean records as
    they are; a cv of its own for it cost ~1.9 s."""
    from fsdecouple.data.calibration import GrossError
    from fsdecouple.evaluation.cv import run_cv

    return json.loads(json.dumps(run_cv(six_calib, six_settings, workers=2,
                                        task=(SIX / "task_voltages.csv", SIX / "task_forces.csv"),
                                        task_tare=TARE_ROWS,
                                        gross_error=GrossError.parse(GROSS, six_settings.layout))))


@pytest.mark.slow  # over ~0.8 s: the not-slow run stays under a minute
def test_cv_runs_every_baseline_on_six_axes(six_cv):
    doc = six_cv
    gammas = [r for r in doc["records"] if r["metric"] == "gamma"]
    assert {r["axis"] for r in gammas} == set(COMPONENTS)
    assert {r["method"] for r in gammas} == {"initial", "linear", "rbf-mimo", "rbf-siso", "svr"}
    worst = {m: max(r["value"] for r in gammas if r["method"] == m) for m in ("initial", "linear",
                                                                              "svr")}
    assert worst["svr"] < worst["linear"] < worst["initial"]  # the coupling is nonlinear
    task = doc["task"]["records"]
    rms = {(r["method"], r["axis"]): r["value"] for r in task if r["metric"] == "rms_error"}
    assert all(rms[("svr", c)] < rms[("linear", c)] for c in COMPONENTS)
    assert len(doc["curves"]["chi"]) == 30


def test_validate_accepts_combined_loads(six_model, six_settings, tmp_path):
    """A lever arm: the fy sweep of a validation set loads fy and mx = 0.02 m x fy at once."""
    from fsdecouple.evaluation.validate import validate

    sensor = six_axis_sensor(0)
    t = simulate_calibration(sensor, 1, seed=9)
    # each row's offset and noise as simulated, then the outputs of the combined load
    drift = t[list(OUTPUTS)].to_numpy() - sensor.voltages(t[list(COMPONENTS)].to_numpy())
    fy = (t["axis"] == "fy").to_numpy()
    t.loc[fy, "mx"] = 0.02 * t.loc[fy, "fy"]
    t[list(OUTPUTS)] = sensor.voltages(t[list(COMPONENTS)].to_numpy()) + drift
    (tmp_path / "set").mkdir()
    t.drop(columns="repetition").to_csv(tmp_path / "set" / "rep1.csv", index=False)
    doc = validate(six_model, tmp_path / "set", six_settings)
    assert any("20 combined-load points" in w for w in doc["warnings"])
    rec = {(r["axis"], r["method"], r["metric"]): r["value"] for r in doc["records"]
           if r["range"] == "calibrated"}
    # the combined points are decoupled as well as single loads: both near the noise.
    # Over sensors and sets of seeds 0-23 (set seed + 9): fy / fx mean 1.05, sd 0.17,
    # max 1.41; fy / initial mean 0.12, sd 0.025, max 0.17 (0.11 here).  Limits: 3 and
    # 0.25, above the max x 1.25 (0.22); undecoupled combined points are 1 x initial.
    assert rec[("fy", "model", "rms_error")] < 3 * rec[("fx", "model", "rms_error")]
    assert rec[("fy", "model", "rms_error")] < 0.25 * rec[("fy", "initial", "rms_error")]


@pytest.mark.slow
def test_report_has_a_panel_per_component_and_every_chi(unrendered, six_model, six_calib, six_cv):
    """The report's figures are built but not rasterised (~9 s of CPU for N = 6); the
    30-panel chi grid, the largest, is drawn and rasterised below, at 20 dpi: drawing its
    panels and text is the point, not its pixels (2.1 s of CPU instead of 3.0 at 110)."""
    from fsdecouple.reporting.plots import to_png
    from fsdecouple.reporting.report import build_report

    report = build_report(six_model, six_cv, six_calib)
    html = report.html
    assert set(report.figures) == {"figure6_omega", "figure7_chi", "residuals"}
    for text in ("χfx:fy", "χmz:my", "γmz", ">mz<", "u6"):
        assert text in html, text
    fig = chi_figure_axes(six_model)
    assert len([ax for ax in fig.axes if ax.get_visible()]) == 30
    assert to_png(fig, dpi=20).startswith(b"\x89PNG\r\n\x1a\n")


def chi_figure_axes(model):
    from fsdecouple.reporting.plots import chi_figure, omega_figure

    assert len([ax for ax in omega_figure(model).axes if ax.get_visible()]) == 6
    return chi_figure(model)


@pytest.mark.slow  # over ~0.8 s: the not-slow run stays under a minute
def test_decouple_frame_and_compare_take_the_layout(six_model, six_calib):
    """compare runs on a lean fit of the sample (an SVR tube of 3e-3 V, Table 2's 1e-4:
    0-5 support vectors a chi instead of ~110).  Its grid of 7^6 combined outputs sums
    every kernel, which cost 2.5 s of CPU with six_model, and the layout's names are the
    point here, not the kernel sums (tests/fleet/test_fleet.py checks compare's figures)."""
    import fsdecouple
    from fsdecouple.fleet.drift import compare

    log = pd.read_csv(SIX / "task_voltages.csv")
    out = fsdecouple.decouple_frame(six_model, log, tare=TARE_ROWS)
    assert list(out.columns) == [*log.columns, *COMPONENTS, "status"]
    u = log[list(OUTPUTS)].to_numpy()
    np.testing.assert_allclose(out[list(COMPONENTS)].to_numpy(),
                               six_model.decouple(u - u[:TARE_ROWS].mean(axis=0)), atol=1e-12)
    lean = fit(six_calib, load_config(CONFIG, epsilon=3e-3))
    doc = compare(lean, lean)
    assert list(doc["components"]) == list(COMPONENTS)
    assert doc["components"]["my"]["chi_max_pct"]["my:fz"] == 0.0


def test_refinement_works_for_six_components(six_model):
    """--refine K: the table path, the exact path and decoupler() agree for N = 6, and
    the refined forces are closer to the truth on noise-free combined loads."""
    truth = six_axis_sensor(0)
    rng = np.random.default_rng(8)
    f = rng.uniform(-0.6, 0.6, (300, 6)) * np.asarray(truth.full_scale)
    u = truth.voltages(f)
    tables, exact = six_model.decouple(u, refine=2), six_model.decouple(u, refine=2, exact=True)
    fs = np.asarray(truth.full_scale)
    assert np.abs((tables - exact) / fs).max() < 1e-9  # the tables' promise, per full scale
    one = six_model.decoupler(refine=2)
    np.testing.assert_allclose([one(*row) for row in u[:20]], tables[:20], rtol=0, atol=1e-12)
    err0 = np.sqrt(np.mean(((six_model.decouple(u) - f) / fs) ** 2))
    err2 = np.sqrt(np.mean(((tables - f) / fs) ** 2))
    assert err2 < err0  # eq. (11)'s second-order error (eq. 6) shrinks with K


@pytest.mark.slow  # over ~0.8 s: the not-slow run stays under a minute
def test_cv_moves_a_point_of_a_named_component(six_settings, six_calib, six_cv):
    from fsdecouple.data.calibration import GrossError
    from fsdecouple.evaluation.cv import run_cv

    ge = GrossError.parse(GROSS, six_settings.layout)
    assert ge.axis == "my"
    # six_cv's run of it, in the default folds (1, 2), (3, 4), (5, 6): repetition 2 is
    # held out in round 1 and trains rounds 2 and 3
    doc = six_cv
    assert doc["folds"] == [[1, 2], [3, 4], [5, 6]]
    assert doc["gross_error"]["spec"] == {"axis": "my", "repetition": 2, "point": 5, "offset": 0.2}
    assert doc["gross_error"]["rounds_affected"] == [2, 3]
    with pytest.raises(InputError, match="AXIS:REP:POINT:OFFSET"):
        GrossError.parse("x:1:5:0.2", six_settings.layout)
    with pytest.raises(InputError, match="no component 'x'"):
        run_cv(six_calib, six_settings, gross_error=GrossError.parse("x:1:5:0.2"))


def _peak_coupling(calibration: pd.DataFrame) -> np.ndarray:
    """Peak |u_a - u_a(zero row)| over sweep b over output a's full-scale swing, (6, 6)."""
    peak = np.zeros((6, 6))
    swing = {}
    for b, (comp, out) in enumerate(zip(COMPONENTS, OUTPUTS, strict=True)):
        sweep = calibration[calibration["axis"] == comp]
        swing[b] = (sweep[out].max() - sweep[out].min()) / 2  # |k_b| F_FS,b
    for b, comp in enumerate(COMPONENTS):
        sweep = calibration[calibration["axis"] == comp]
        zero = sweep[sweep[comp] == 0].iloc[0]
        for a, out in enumerate(OUTPUTS):
            if a != b:
                peak[a, b] = (sweep[out] - zero[out]).abs().max() / swing[a]
    return peak


def test_simulate_six_axis_with_coupling_sets_every_peak(tmp_path):
    invoke(["simulate", tmp_path / "own", "--components", "6", "--repetitions", "1"])
    invoke(["simulate", tmp_path / "strong", "--components", "6", "--repetitions", "1",
            "--coupling", "0.05"])
    own = _peak_coupling(pd.read_csv(tmp_path / "own" / "calibration" / "rep1.csv"))
    strong = _peak_coupling(pd.read_csv(tmp_path / "strong" / "calibration" / "rep1.csv"))
    off = ~np.eye(6, dtype=bool)
    assert own[off].max() < 0.025  # the seed's own peaks: 0.2-1.75 % plus noise
    # every pair peaks at 5 % of its output's full scale, read back from the written outputs;
    # the 21-point grid can miss the peak between points, and the noise adds a little
    assert strong[off].min() > 0.035 and strong[off].max() < 0.055


def test_simulate_six_axis_with_a_gross_error_moves_one_prime_output(tmp_path):
    invoke(["simulate", tmp_path / "clean", "--components", "6", "--repetitions", "2"])
    invoke(["simulate", tmp_path / "gross", "--components", "6", "--repetitions", "2",
            "--gross-error", "my:2:7:0.25"])
    clean, gross = (pd.read_csv(tmp_path / d / "calibration" / "rep2.csv") for d in ("clean", "gross"))
    diff = gross[list(OUTPUTS)].to_numpy() - clean[list(OUTPUTS)].to_numpy()
    rows, cols = np.nonzero(diff)
    my_rows = np.flatnonzero(clean["axis"] == "my")
    assert rows.tolist() == [my_rows[6]] and cols.tolist() == [OUTPUTS.index("u5")]
    assert diff[rows[0], cols[0]] == pytest.approx(0.25, abs=1e-7)
    assert (pd.read_csv(tmp_path / "gross" / "calibration" / "rep1.csv")
            .equals(pd.read_csv(tmp_path / "clean" / "calibration" / "rep1.csv")))
    bad = invoke(["simulate", tmp_path / "bad", "--components", "6", "--gross-error", "x:1:5:0.2"],
                 code=2)
    assert "fx, fy, fz, mx, my, mz" in bad.stderr and not (tmp_path / "bad").exists()


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_validate_shows_mixed_unit_errors_in_full_scale_only(six_model_file, sample_model):
    """Forces and moments have no one unit: the table keeps % F.S. and drops the
    absolute columns a 3-axis model shows in its load unit."""
    shown = invoke(["validate", six_model_file, SIX / "calibration", "-c", CONFIG]).stdout
    assert "max % F.S." in shown and "N / N·m]" not in shown
    assert "no one unit, so the errors are in % F.S. only" in shown.replace("\n", " ")
    # sample_model (conftest.py): `fsdecouple fit` of sample_data/calibration
    assert "max [N]" in invoke(["validate", sample_model, SAMPLE / "calibration"]).stdout
