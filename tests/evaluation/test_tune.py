"""fit --tune: the grid, the held-out choice, the record in the model file, bad input."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from conftest import FAST_CONFIG
from typer.testing import CliRunner

from fsdecouple import load_config
from fsdecouple.cli import app
from fsdecouple.config import SVRSettings
from fsdecouple.core.modelfile import load_model, model_to_dict
from fsdecouple.data.calibration import from_table, load_calibration
from fsdecouple.errors import InputError
from fsdecouple.evaluation.heldout import rounds_for
from fsdecouple.evaluation.tune import (
    TUNE_TOLERANCE,
    Grid,
    clearly_better,
    edge_round,
    parse_grid,
    tune_settings,
)
from fsdecouple.fitting.fit import chi_training_data, fit
from fsdecouple.fitting.linear import fit_omega
from fsdecouple.fitting.svr import predict, train
from fsdecouple.sim.simulate import SimulatedSensor, with_coupling

runner = CliRunner()
SAMPLE = "sample_data/calibration"
# the module's grid: C x epsilon at the narrow gamma = 8 (the calibrated-range check's
# candidate is one of them); a second gamma only added fits (the product is C x epsilon's)
SMALL = "gamma=8;C=1,10;epsilon=0.25,1"
# two candidates besides Table 2: enough for the CLI's record and round trip (the grid
# itself is checked on SMALL through the `tuned` fixture).  Wide kernels at C = 1 solve
# fast (0.9 s of CPU for the tune, 1.6 s with gamma 1 and 8 at C = 10), and with Table
# 2's tolerance (FAST_CONFIG) both are clearly better on the sample, the second chosen
# (figures 7.8e-4 and 7.5e-4 F.S. against 9.0e-4): the round trips carry a grid pick
TINY = "gamma=2,4;C=1;epsilon=1"


@pytest.fixture(scope="module")
def tuned():
    # Table 2 at its own libsvm tolerance (1e-3, as a config writes it): its figure is
    # re-derived here with the same settings, and the narrow candidate beats it inside
    # and loses at the edge either way (measured: figure 7.3e-4 against 9.0e-4 F.S., 7.8e-4
    # at the noise rule; edge 1.38e-3 against 1.10e-3, 1.22e-3).  Its fits at the noise
    # rule cost 3x: 7.7 s of CPU instead of 2.5 s for the tune and the re-derivation.
    # The noise rule's record (tolerance None) is test_every_candidate_better_inside's.
    settings = load_config(tolerance=1e-3)
    calib = load_calibration(SAMPLE, settings)
    chosen, record = tune_settings(calib, settings, grid=parse_grid(SMALL), workers=2)
    return calib, settings, chosen, record


@pytest.mark.slow  # a tuning grid of fits: seconds of CPU; the not-slow run stays under a minute
def test_table2_is_candidate_zero_and_its_figure_is_rederived(tuned):
    calib, settings, _, record = tuned
    t2 = record["candidates"][0]
    assert t2["table2"] and (t2["gamma"], t2["C"], t2["epsilon"]) == (0.5, 1000.0, 1e-4)
    assert t2["scaling"] == settings.scaling
    assert len(record["candidates"]) == 1 + 1 * 2 * 2
    # the held-out RMS of Table 2, computed here from the rounds and plain fits
    sq, n = np.zeros(3), 0
    for rnd in rounds_for(calib, "repetitions"):
        model = fit(rnd.train, settings, workers=1, tables=False)
        for _, test in rnd.tests:
            f = model.decouple(test.voltages, rotate=False, exact=True)
            sq += ((f - test.forces) ** 2).sum(axis=0)
            n += len(f)
    assert [t2["rms"][a] for a in "xyz"] == pytest.approx(np.sqrt(sq / n), rel=1e-9)
    assert t2["figure"] == pytest.approx(max(np.sqrt(sq / n) / settings.full_scale), rel=1e-9)


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_never_worse_than_table2(tuned):
    _, _, chosen, record = tuned
    cands = record["candidates"]
    pick, t2 = cands[record["chosen"]], cands[0]
    assert pick["figure"] <= t2["figure"]
    # the figure is the worst axis's held-out RMS / F.S., re-derived from the per-axis RMS
    fs = dict(zip("xyz", load_config().full_scale, strict=True))
    for c in cands:
        assert c["figure"] == pytest.approx(max(c["rms"][a] / fs[a] for a in "xyz"), rel=1e-12)
    assert all(c["figure"] >= pick["figure"] for c in cands if c["clearly_better"])
    assert (chosen.svr.gamma, chosen.svr.C, chosen.svr.epsilon, chosen.scaling) == (
        pick["gamma"], pick["C"], pick["epsilon"], pick["scaling"])
    # epsilon as multiples of the measured noise
    assert record["epsilon_basis"] == "noise" and 1e-4 < record["noise"] < 1e-3
    assert sorted({c["epsilon"] for c in cands[1:]}) == pytest.approx(
        [0.25 * record["noise"], record["noise"]])


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_grid_candidates_are_solved_to_the_tuned_tolerance(tuned):
    _, settings, chosen, record = tuned
    cands = record["candidates"]
    # as configured (here Table 2's 1e-3), not the grid's
    assert cands[0]["tolerance"] == settings.svr.tolerance == 1e-3
    assert all(c["tolerance"] == TUNE_TOLERANCE for c in cands[1:])
    if record["chosen"]:
        assert chosen.svr.tolerance == TUNE_TOLERANCE


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_the_tuned_tolerance_reaches_the_converged_svr_and_table2s_does_not():
    # Why grid candidates get their own tolerance: libsvm's stopping tolerance is in
    # the target's units (here fractions of F.S.), and Table 2's 1e-3 is larger than
    # the noise (~4e-4 F.S.), so the solver stops well short of the optimum.  The
    # reference is the same problem solved to 1e-9.
    settings = load_config()
    calib = load_calibration(SAMPLE, settings)
    # the SVRs' full-scale units: |k| F_FS, k the slopes of eq. (2) (the fit's own k,
    # without the 1 s of its six SVRs)
    u_fs = np.abs(fit_omega(calib.points, calib.layout).k) * np.asarray(settings.full_scale)
    x, y = chi_training_data(calib, "yx")
    x, y = x / u_fs[0], y / u_fs[1]
    grid = np.linspace(x.min(), x.max(), 101)

    def chi(tolerance):
        return predict(train(x, y, SVRSettings(C=10.0, epsilon=4e-4, gamma=4.0,
                                               tolerance=tolerance)), grid)

    converged = chi(1e-9)
    # measured: 3.7e-5 and 5.7e-4 F.S.; the noise sigma is ~4e-4 F.S.
    assert np.abs(chi(TUNE_TOLERANCE) - converged).max() < 1e-4
    assert np.abs(chi(1e-3) - converged).max() > 3e-4


def test_edge_round_holds_out_each_sweeps_loads_beyond_its_others():
    settings = load_config()
    calib = load_calibration(SAMPLE, settings)
    rnd = edge_round(calib)
    test = rnd.tests[0][1].points
    # the sample's grids (Section 3): X and Y from -100 to 100 N, Z from 0 to -150 N;
    # the zero rows stay in training, so Z's only end is -150 N
    ends = {"x": {-100.0, 100.0}, "y": {-100.0, 100.0}, "z": {-150.0}}
    reps = calib.repetitions
    assert len(test) == len(reps) * 5 and len(rnd.train.points) + len(test) == len(calib.points)
    for (axis, rep), g in test.groupby(["axis", "repetition"]):
        assert set(g["f" + axis]) == ends[axis] and rep in reps
    for axis, loads in ends.items():  # none left in training
        assert not rnd.train.sweep(axis)["f" + axis].isin(loads).any()


@pytest.mark.slow  # a tune of one candidate, and the module's grid (SMALL holds it)
def test_the_calibrated_range_decides_and_the_edge_only_with_kernel_extrapolation(tuned):
    # gamma = 8 per F.S.^2: better than Table 2 on the held-out points inside the
    # loads (figure), worse extrapolating one load step (edge): its kernel is narrow.
    # With tangent extrapolation (the default) beyond the range is the tangent's, and
    # the candidate is chosen; with the kernel sum beyond the range it is not (issue 24).
    # The tangent side is read from the module's tune of SMALL (the same candidate, on
    # the same rounds: its figure, edge and clearly_better do not depend on the others)
    calib, settings, chosen, record = tuned
    assert settings.extrapolation == "tangent"
    t2 = record["candidates"][0]
    narrow, = (c for c in record["candidates"]
               if (c["gamma"], c["C"]) == (8.0, 10.0)
               and c["epsilon"] == pytest.approx(0.25 * record["noise"]))
    assert narrow["figure"] < t2["figure"] and narrow["edge"] > t2["edge"]
    assert narrow["clearly_better"] and record["chosen"] != 0
    pick = record["candidates"][record["chosen"]]
    assert record["beyond_range"] == "extrapolation" and chosen.svr.gamma == pick["gamma"]
    grid = Grid(gamma=(8.0,), C=(10.0,), epsilon=(0.25,))
    kernel = replace(settings, extrapolation="kernel")
    chosen, record = tune_settings(calib, kernel, grid=grid, workers=2)
    t2, narrow = record["candidates"]
    assert narrow["figure"] < t2["figure"] and narrow["edge"] > t2["edge"]
    assert not narrow["clearly_better"] and record["chosen"] == 0 and chosen == kernel
    assert record["beyond_range"] == "edge"


def _scripted(monkeypatch, inside, edge):
    """heldout_errors replaced: per candidate, these squared errors inside and at the edge."""
    import fsdecouple.evaluation.tune as tune

    def errors(calib, settings, cands, rounds, workers=None, progress=None):
        return [np.concatenate([i, e]) for i, e in zip(inside, edge, strict=True)][:len(cands)]

    monkeypatch.setattr(tune, "heldout_errors", errors)


def test_every_candidate_better_inside_is_not_given_up_for_the_edge(monkeypatch):
    """Issue 24's sensor in small: every candidate beat Table 2 on the held-out points and
    lost one load step beyond the range; the old rule kept Table 2.  Now the best inside
    is chosen (tangent extrapolation), and the edge figures are still recorded."""
    settings = load_config()
    calib = load_calibration(SAMPLE, settings)
    n_in = sum(len(t.points) for r in rounds_for(calib, "repetitions") for _, t in r.tests)
    n_edge = len(edge_round(calib).tests[0][1].points)
    rng = np.random.default_rng(3)
    base = rng.chisquare(1, size=(n_in, 3)) * 1e-6
    grid = Grid(gamma=(2.0, 4.0), C=(10.0,), epsilon=(0.5,))
    inside = [base, base * 0.64, base * 0.6]  # figures: 1, 0.8, 0.77 of Table 2's
    edge = [np.full((n_edge, 3), 1e-6), np.full((n_edge, 3), 3e-6), np.full((n_edge, 3), 4e-6)]
    _scripted(monkeypatch, inside, edge)
    _, record = tune_settings(calib, settings, grid=grid, workers=1)
    assert record["chosen"] == 2  # the lowest figure, though the worst at the edge
    # Table 2 as configured: none written, so fit's noise rule (None), never a figure it
    # does not use; the grid's candidates at TUNE_TOLERANCE
    assert record["candidates"][0]["tolerance"] is settings.svr.tolerance is None
    assert all(c["tolerance"] == TUNE_TOLERANCE for c in record["candidates"][1:])
    assert [c["edge"] for c in record["candidates"]] == pytest.approx([1e-3, 3 ** 0.5 * 1e-3,
                                                                       2e-3])
    _, record = tune_settings(calib, replace(settings, extrapolation="kernel"), grid=grid,
                              workers=1)
    assert record["chosen"] == 0  # kernel sum beyond the range: the edge still decides


@pytest.mark.slow  # a tuning grid of fits: seconds of CPU; the not-slow run stays under a minute
def test_a_candidate_worse_than_table2_on_any_axis_is_never_chosen(monkeypatch):
    # a grid of one bad candidate (far too narrow a kernel): Table 2 stays.  C = 10: the
    # held-out figure is 3.9x Table 2's (C = 1000: 106x, and 6x the libsvm time).  Table 2
    # at its own tolerance (1e-3, as a config writes it): the candidate's loss is far
    # beyond the difference that makes to Table 2's figure
    settings = load_config(tolerance=1e-3)
    calib = load_calibration(SAMPLE, settings)
    chosen, record = tune_settings(calib, settings, grid=Grid(gamma=(5000.0,), C=(10.0,),
                                                              epsilon=(0.5,)), workers=2)
    assert record["candidates"][1]["figure"] > record["candidates"][0]["figure"]
    assert record["chosen"] == 0 and chosen == settings


@pytest.mark.slow  # over ~0.8 s: the not-slow run stays under a minute
def test_fit_tune_round_trips_through_the_model_file(tmp_path):
    out = tmp_path / "m.json"
    # the record is the tune's, verdict or not; Table 2's tolerance: the record is the point
    r = runner.invoke(app, ["fit", SAMPLE, "-o", str(out), "--tune", "--tune-grid", TINY,
                            "-c", str(FAST_CONFIG), "--json", "--no-verdict"])
    assert r.exit_code == 0, r.output
    printed = json.loads(r.stdout)["tune"]
    assert printed["chosen"] != 0  # a grid candidate, not Table 2's settings
    model = load_model(out)
    assert model.report.tune == printed
    pick = printed["candidates"][printed["chosen"]]
    assert (model.settings.svr.gamma, model.settings.svr.C, model.settings.svr.epsilon) == (
        pick["gamma"], pick["C"], pick["epsilon"])
    assert all(c.gamma == pick["gamma"] for c in model.chi.values())
    assert model_to_dict(model)["report"]["tune"] == printed


@pytest.mark.slow  # a fit: about a second of CPU
def test_untuned_models_have_no_tune_record(tmp_path, sample_model):
    out = tmp_path / "m.json"
    r = runner.invoke(app, ["fit", SAMPLE, "-o", str(out), "-c", str(FAST_CONFIG), "--json",
                            "--no-verdict"])  # Table 2's tolerance: the record is the point
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["tune"] is None
    for path in (out, sample_model):  # and the session's fit with its verdict
        assert "tune" not in json.loads(path.read_text())["report"]  # older files' bytes
        assert load_model(path).report.tune is None


@pytest.mark.parametrize("grid", ["gamma=0", "C=1e9", "epsilon=-1", "gamma=nan", "delta=1",
                                  "gamma=1,1", "gamma=a"])
def test_grid_outside_its_range_is_one_line_exit_2(tmp_path, grid):
    out = tmp_path / "m.json"
    r = runner.invoke(app, ["fit", SAMPLE, "-o", str(out), "--tune", "--tune-grid", grid])
    assert r.exit_code == 2
    assert "--tune-grid" in r.output and len(r.output.strip().splitlines()) == 1
    assert not out.exists()


def test_tune_grid_needs_tune(tmp_path):
    r = runner.invoke(app, ["fit", SAMPLE, "-o", str(tmp_path / "m.json"), "--tune-grid", SMALL])
    assert r.exit_code == 2 and "--tune" in r.output
    assert not (tmp_path / "m.json").exists()


def test_tune_of_a_linear_model_is_refused(tmp_path):
    """fit --method linear --tune fitted and scored the whole grid for a model with no SVR."""
    out = tmp_path / "m.json"
    r = runner.invoke(app, ["fit", SAMPLE, "-o", str(out), "--method", "linear", "--tune"])
    assert r.exit_code == 2 and len(r.output.strip().splitlines()) == 1
    assert "--tune: tuning chooses the SVRs' gamma, C and epsilon" in r.output
    assert not out.exists()


def test_tune_on_a_set_too_small_for_the_held_out_protocol(tmp_path):
    # one repetition (levels protocol) with one loaded point per sweep: nothing to hold out
    rows = ["axis,fx,fy,fz,ux,uy,uz"]
    for a, axis in enumerate("xyz"):
        rows.append(f"{axis},0,0,0,0.01,0.02,0.03")
        f = ["0", "0", "0"]
        f[a] = "50"
        u = [0.011, 0.021, 0.031]
        u[a] += 0.6
        rows.append(f"{axis},{','.join(f)},{','.join(map(str, u))}")
    (tmp_path / "cal.csv").write_text("\n".join(rows) + "\n")
    (tmp_path / "c.yaml").write_text("min_repetitions: 1\n")
    out = tmp_path / "m.json"
    r = runner.invoke(app, ["fit", str(tmp_path / "cal.csv"), "-c", str(tmp_path / "c.yaml"),
                            "-o", str(out), "--tune"])
    assert r.exit_code == 2, r.output
    assert "--tune" in r.output and len(r.output.strip().splitlines()) == 1
    assert not out.exists()
    # what fit's advice asks before it recommends --tune (it recommended it here)
    from fsdecouple.evaluation.tune import tunable

    settings = load_config(tmp_path / "c.yaml")
    assert not tunable(load_calibration(tmp_path / "cal.csv", settings))
    assert tunable(load_calibration(SAMPLE, load_config()))


def test_an_epsilon_grid_needs_a_measured_sigma():
    """With one repetition epsilon=0.5,2 (multiples of sigma) was replaced in silence by
    the fixed fractions of full scale, while the model's record still said 0.5, 2."""
    from fsdecouple.evaluation.tune import EPSILON_FIXED, candidates

    settings = load_config()
    with pytest.raises(InputError, match="epsilon is in multiples of the calibration's noise sigma"):
        candidates(settings, parse_grid("epsilon=0.5,2"), None)
    with pytest.raises(InputError, match="epsilon is in multiples"):  # the Python API's too
        candidates(settings, Grid(epsilon=(0.5, 2.0)), None)
    cands, basis = candidates(settings, parse_grid("C=3"), None)  # epsilon left out: fixed
    assert basis == "fixed" and sorted({c.epsilon for c in cands[1:]}) == list(EPSILON_FIXED)
    cands, basis = candidates(settings, parse_grid("epsilon=0.5,2"), 0.01)
    assert basis == "noise" and sorted({c.epsilon for c in cands[1:]}) == [0.005, 0.02]


def test_parse_grid_keeps_defaults_for_keys_left_out():
    g = parse_grid("C=3")
    assert g.C == (3.0,) and g.gamma == Grid().gamma and g.epsilon == Grid().epsilon
    with pytest.raises(InputError):
        parse_grid("C=1;C=2")


# --- the hidden check, in small -------------------------------------------------------------


def floor_forces(sensor: SimulatedSensor, u: np.ndarray) -> np.ndarray:
    """Eq. (1) solved exactly with the simulator's true coupling functions."""
    f = u / sensor.k
    for _ in range(300):
        f = (u - (sensor.voltages(f) - f * sensor.k)) / sensor.k
    return f


def _ratio_to_floor(tmp_path, coupling, fit_args):
    from fsdecouple.sim.simulate import SimulatedSensor

    if "--tune-grid" in fit_args:  # a part of the default grid
        g, default = parse_grid(fit_args[fit_args.index("--tune-grid") + 1]), Grid()
        assert all(set(getattr(g, k)) <= set(getattr(default, k)) for k in ("gamma", "C", "epsilon"))
    sim = ["simulate", str(tmp_path / "d"), "--seed", "7"]
    sensor = SimulatedSensor()
    if coupling is not None:
        sim += ["--coupling", str(coupling)]
        sensor = with_coupling(sensor, coupling)
    assert runner.invoke(app, sim).exit_code == 0
    # --no-verdict: the verdict only reports (method svr decouples as fitted either way)
    r = runner.invoke(app, ["fit", str(tmp_path / "d" / "calibration"), "-o",
                            str(tmp_path / "m.json"), "--no-verdict", *fit_args])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["apply", str(tmp_path / "m.json"), str(tmp_path / "d" / "task_voltages.csv"),
                            "-o", str(tmp_path / "f.csv"), "--tare", "200"])
    assert r.exit_code == 0, r.output
    got = pd.read_csv(tmp_path / "f.csv")[["fx", "fy", "fz"]].to_numpy()
    truth = pd.read_csv(tmp_path / "d" / "task_forces.csv")[["fx", "fy", "fz"]].to_numpy()
    u = pd.read_csv(tmp_path / "d" / "task_voltages.csv")[["ux", "uy", "uz"]].to_numpy()
    u = u - u[:200].mean(axis=0)
    floor = np.sqrt(np.mean((floor_forces(sensor, u) - truth) ** 2, axis=0))
    return np.sqrt(np.mean((got - truth) ** 2, axis=0)) / floor


# The limits come from the scatter over simulate's seeds 1-24 (_ratio_to_floor with
# --seed s, --tune --refine 3), worst axis of each seed:
#   coupling 0.05:    mean 1.34, sd 0.18, max 1.93 (seed 19); seed 7: 1.38
#   coupling 0.0175:  mean 1.35, sd 0.22, max 2.21 (seed 19); seed 7: 1.32
# 1.5 held on seed 7 but not on 3 of the 24 seeds at either coupling.  Limits: the
# max x 1.25, rounded.
FIVE_PERCENT_LIMIT, SAMPLE_LIKE_LIMIT = 2.4, 2.75
# The tests tune on part of the default grid that holds the candidate the default grid
# (24 candidates) chooses on seed 7, measured with --tune alone: gamma 4, C 1, epsilon
# 0.25 sigma at coupling 0.05 (figure 6.26e-4 F.S.), gamma 2, C 10, epsilon 0.25 sigma
# at 0.0175 (6.05e-4), each the lowest figure of those clearly better than Table 2.
# Each candidate is judged against Table 2 alone and the lowest figure of those clearly
# better is chosen, so these grids choose the same settings and the ratios are the
# default grid's to the last digit (measured: 1.246, 1.081, 1.376 and 1.271, 1.068,
# 1.315): the limits above hold for them as derived.  Beside the winner, gamma 2, C 1,
# epsilon 0.25 sigma: clearly better but a higher figure at 0.05 (6.44e-4), not clearly
# better at 0.0175.  A tune of 3 candidates instead of 25: ~3.3 s of CPU a test, not ~13 s.
FIVE_PERCENT_GRID = "gamma=2,4;C=1;epsilon=0.25"
SAMPLE_LIKE_GRID = "gamma=2;C=1,10;epsilon=0.25"


@pytest.mark.slow
def test_five_percent_coupling_tuned_and_refined_is_near_the_floor(tmp_path):
    ratio = _ratio_to_floor(tmp_path, 0.05, ["--tune", "--tune-grid", FIVE_PERCENT_GRID, "--refine", "3"])
    assert (ratio <= FIVE_PERCENT_LIMIT).all(), ratio


@pytest.mark.slow
def test_sample_like_coupling_tuned_and_refined_is_near_the_floor(tmp_path):
    """At the sample's coupling the defaults (K = 0, Table 2) reach 1.2-1.8x the floor per
    axis on simulate's log (docs/benchmarks.md, the accuracy table); tune + refine close most of it."""
    ratio = _ratio_to_floor(tmp_path, 0.0175, ["--tune", "--tune-grid", SAMPLE_LIKE_GRID,
                                                  "--refine", "3"])
    assert (ratio <= SAMPLE_LIKE_LIMIT).all(), ratio  # seed 7: 1.32x; see the scatter above


@pytest.mark.slow  # over ~0.8 s: the not-slow run stays under a minute
def test_cv_tune_records_the_choice_and_cross_validates_with_it(tmp_path):
    out = tmp_path / "cv.json"
    r = runner.invoke(app, ["cv", SAMPLE, "--tune", "--tune-grid", TINY, "-c", str(FAST_CONFIG),
                            "-o", str(out)])  # Table 2's tolerance: the record is the point
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    assert doc["tune"]["chosen"] != 0  # a grid candidate, not Table 2's settings
    pick = doc["tune"]["candidates"][doc["tune"]["chosen"]]
    assert (doc["settings"]["svr"]["gamma"], doc["settings"]["scaling"]) == (
        pick["gamma"], pick["scaling"])
    r = runner.invoke(app, ["cv", SAMPLE, "--tune-grid", "gamma=0", "-o", str(tmp_path / "b.json")])
    assert r.exit_code == 2 and not (tmp_path / "b.json").exists()


def test_clearly_better_needs_a_lower_figure_and_a_gain_beyond_the_noise():
    rng = np.random.default_rng(1)
    t2 = rng.chisquare(1, size=(400, 3)) * np.array([1.0, 1.0, 2.0])  # z is Table 2's worst axis
    # 20 % lower on z, 10 % higher on x (still below z): the figure is lower, so it may win
    better = t2 * np.array([1.1, 1.0, 0.8])
    assert clearly_better(better, t2, margin=1.0)
    # on 16 points, a gain on z of 0.1 that comes with +-2 of scatter: lower on
    # average, but within one standard error (2 / sqrt(16)) of the paired difference
    few = t2[:16] + 3.0
    noisy = few.copy()
    noisy[:, 2] += -0.1 + 2.0 * np.resize([1.0, -1.0], 16)
    d = noisy[:, 2] - few[:, 2]
    assert 0 < -d.mean() < d.std() / 4  # what the case is: a gain below 1 SE (sqrt(16) = 4)
    assert not clearly_better(noisy, few, margin=1.0)
    assert clearly_better(noisy, few, margin=0.0)
    # lower on z but a new worst axis above Table 2's figure: never
    shifted = t2 * np.array([2.5, 1.0, 0.5])
    assert not clearly_better(shifted, t2, margin=0.0)


def test_no_edge_round_when_an_axis_would_keep_too_little_to_train():
    # every sweep loaded at -50 and +50 only: both are ends, nothing loaded is left
    rows = [("x", 1, 0.0), ("x", 1, -50.0), ("x", 1, 50.0)]
    table = pd.DataFrame([(1, a, *(f if a == b else 0.0 for b in "xyz"), 0.0, 0.0, 0.0)
                          for a in "xyz" for _, _, f in rows],
                         columns=["repetition", "axis", "fx", "fy", "fz", "ux", "uy", "uz"])
    calib = from_table(table, replace(load_config(), min_repetitions=1))
    assert edge_round(calib) is None
    assert edge_round(load_calibration(SAMPLE, load_config())) is not None
