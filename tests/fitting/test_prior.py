"""``fit NEW --prior OLD.json`` (issue 32 item 7, fitting/prior.py): the old model with its
matrix and zero ridge-corrected, or a fresh fit, whichever held-out error prefers."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from conftest import assert_one_line_error, invoke

from fsdecouple.config import load_config
from fsdecouple.core.modelfile import load_model, save_model
from fsdecouple.data.calibration import load_calibration
from fsdecouple.data.init_config import init_config
from fsdecouple.evaluation.calibrate import fit
from fsdecouple.fitting.prior import (
    FRESH,
    _decoder,
    _jacobian,
    choose_prior,
    corrected_model,
    fit_correction,
    fit_with_prior,
    with_prior,
    zero_shift,
)
from fsdecouple.sim.poses import PoseSet, pose_lines, simulate_poses
from fsdecouple.sim.rig import write_rig


@pytest.fixture(scope="module")
def old(tmp_path_factory):
    """A model of simulated sensor 0 from all its 60 poses, its config and its data."""
    tmp = tmp_path_factory.mktemp("old")
    path = tmp / "poses.csv"
    path.write_text("\n".join(pose_lines(simulate_poses(0, 30))) + "\n")
    init_config(path, tmp / "cfg.yaml")
    invoke(["fit", path, "-c", tmp / "cfg.yaml", "-o", tmp / "old.json", "--no-verdict"])
    return tmp, load_model(tmp / "old.json"), load_config(tmp / "cfg.yaml")


def test_a_known_change_of_gains_and_offsets_comes_back(old):
    # outputs whose old model is known exactly: u = (x - b) / (1 + alpha) of the old set's
    # x, loaded with what the old model decodes from x; the fit must find alpha and the
    # offset it makes in the loads, c = P b [F.S.], to the Gauss-Newton's convergence
    tmp, model, settings = old
    calib = load_calibration(tmp / "poses.csv", settings)
    x = calib.voltages
    g = _decoder(model, exact=True)
    p = model.projection
    fs = np.asarray(settings.full_scale, dtype=float)
    rng = np.random.default_rng(5)
    alpha = 0.03 * rng.normal(size=x.shape[1])
    b = 5.0 * rng.normal(size=x.shape[1])  # counts, of a ~260-count span
    u = (x - b) / (1 + alpha)
    f = model.decouple(x, rotate=False, exact=True)
    corr = fit_correction(u, f, g, p, fs, _jacobian(g, u @ p.T, fs), 0.0, np.inf, True)
    np.testing.assert_allclose(corr.alpha, alpha, atol=1e-6)
    np.testing.assert_allclose(corr.c, p @ b / fs, atol=1e-6)  # [F.S.]
    np.testing.assert_array_equal(corr.d, 0.0)  # lambda_load = inf: D stays the old model's
    # the corrected model decodes u exactly as the old one decodes x
    np.testing.assert_allclose(g(u @ corr.projection(p, fs).T + corr.c * fs) / fs, f / fs, atol=1e-6)


def test_prior_rows_carry_the_old_models_loads(old):
    tmp, model, settings = old
    calib = load_calibration(tmp / "poses.csv", settings)
    out = with_prior(calib, model, 2)
    n = len(calib.points)
    assert len(out.points) == 3 * n
    u = out.points[list(calib.layout.outputs)].to_numpy()
    np.testing.assert_array_equal(u[n:2 * n], u[:n])
    np.testing.assert_allclose(out.points[list(calib.layout.loads)].to_numpy()[n:2 * n],
                               model.decouple(u[:n], rotate=False, exact=True), atol=1e-9)
    # the old model's own calibration: its zero needs (almost) no shift
    delta = zero_shift(model, calib.voltages, calib.forces)
    assert np.abs(delta).max() < 1.0  # counts, of readings ~500


@pytest.fixture(scope="module")
def prior_fit(old):
    """``fit NEW --prior OLD.json`` through the CLI, once: 12 poses of the drifted sensor,
    the old model's config (``method: auto``, as init writes it for poses)."""
    tmp, _, _ = old
    new = tmp / "new.csv"
    drifted = simulate_poses(0, 30, drift=0.01, noise_seed=1)
    few = PoseSet(drifted.loads[::5], drifted.samples[::5], drifted.truth[::5], drifted.railing)
    new.write_text("\n".join(pose_lines(few)) + "\n")
    import fsdecouple.fitting.prior as prior

    chosen, choose = [], prior.choose_prior

    def spy(*args, **kwargs):  # the choice the command made, kept for the checks below
        chosen.append(choose(*args, **kwargs))
        return chosen[-1]

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(prior, "choose_prior", spy)
        r = invoke(["fit", new, "-c", tmp / "cfg.yaml", "-o", tmp / "new.json",
                    "--prior", tmp / "old.json", "--no-verdict"])
    assert len(chosen) == 1
    return new, r, chosen[0]


@pytest.mark.slow  # a whole prior fit: its lambda grid over held-out folds
def test_fit_with_a_prior_says_what_it_chose_and_writes_it(old, prior_fit):
    tmp, model, settings = old
    new, r, choice = prior_fit  # the command's own choice (choose_prior, spied on)
    assert "prior model" in r.stderr and "chosen by held-out worst component's RMS error" in r.stderr
    calib = load_calibration(new, settings)
    assert choice.scores[choice.best] == min(choice.scores.values()) and FRESH in choice.scores
    assert choice.best.replace(" ", "") in r.stderr.replace(" ", "").replace("\n", "")
    # the file decodes the new set's raw outputs as the model of that choice does
    written = load_model(tmp / "new.json")
    mine = (corrected_model(calib, settings, model, choice) if choice.lambdas is not None
            else fit(calib, settings, verdict=False))
    raw = calib.voltages + calib.offsets[list(calib.layout.outputs)].to_numpy().mean(axis=0)
    np.testing.assert_allclose(written.decouple(raw, zero="fitted", rotate=False, exact=True),
                               mine.decouple(raw, zero="fitted", rotate=False, exact=True),
                               atol=1e-9)


def test_a_prior_of_another_sensor_is_refused(tmp_path, rig_model):
    path = tmp_path / "poses.csv"
    path.write_text("\n".join(pose_lines(simulate_poses(0, 10))) + "\n")
    init_config(path, tmp_path / "cfg.yaml")
    # a rig's model (six outputs, not the poses' eight gauges): the session's rig fit, written
    save_model(rig_model, tmp_path / "rig.json")
    r = invoke(["fit", path, "-c", tmp_path / "cfg.yaml", "-o", tmp_path / "m.json",
                "--prior", tmp_path / "rig.json"], code=2)
    assert_one_line_error(r, "--prior", "same sensor and layout")
    assert not (tmp_path / "m.json").exists()


def test_a_prior_with_tuning_is_refused_not_ignored(old):
    tmp, _, _ = old
    r = invoke(["fit", tmp / "poses.csv", "-c", tmp / "cfg.yaml", "-o", tmp / "t.json",
                "--prior", tmp / "old.json", "--tune"], code=2)
    assert_one_line_error(r, "--prior", "tuning")
    assert not (tmp / "t.json").exists()
    r = invoke(["fit", tmp / "poses.csv", "-c", tmp / "cfg.yaml", "-o", tmp / "t.json",
                "--prior", tmp / "old.json", "--method", "linear"], code=2)
    assert_one_line_error(r, "--prior", "method linear")
    assert not (tmp / "t.json").exists()


@pytest.mark.slow  # reads the module's prior fit
def test_a_config_method_a_prior_cannot_obey_is_named_not_dropped(old, prior_fit):
    """init writes method: auto for poses; with a prior the choice is the prior's, and the
    fit says the config's method was not used (an unused key is warned about).  The
    module's prior fit (``prior_fit``) ran with that config."""
    tmp, _, _ = old
    assert "method: auto" in (tmp / "cfg.yaml").read_text()
    assert "config method: auto not used" in prior_fit[1].output


@pytest.fixture(scope="module")
def old_models(tmp_path_factory):
    """Per seed, the old sensor's config and model (fitted once, for both kinds of drift)."""
    made = {}

    def of(seed: int):
        if seed not in made:
            tmp = tmp_path_factory.mktemp(f"old{seed}")
            (tmp / "old.csv").write_text("\n".join(pose_lines(simulate_poses(seed, 60))) + "\n")
            init_config(tmp / "old.csv", tmp / "cfg.yaml")
            settings = load_config(tmp / "cfg.yaml")
            made[seed] = settings, fit(load_calibration(tmp / "old.csv", settings), settings,
                                       verdict=False)
        return made[seed]

    return of


def _errors(seed: int, kind: str, tmp, old_models) -> tuple[float, float, float]:
    """benchmarks/prior.py's protocol, smaller: (old, fresh, prior) worst component's RMS
    error [F.S.] on all 60 poses of the drifted sensor, from 10 new poses."""
    settings, model = old_models(seed)
    moved = {"drift": 0.03} if kind == "gain" else {"coupling": 0.03}
    new = simulate_poses(seed, 60, noise_seed=1, **moved)
    top = 1023.0
    clear = np.flatnonzero(((new.truth > 0.06 * top) & (new.truth < 0.94 * top)).all(axis=1))
    pick = np.sort(np.random.default_rng(seed).choice(clear, 10, replace=False))
    few = PoseSet(new.loads[pick], [new.samples[i] for i in pick], new.truth[pick], new.railing)
    (tmp / "new.csv").write_text("\n".join(pose_lines(few)) + "\n")
    calib = load_calibration(tmp / "new.csv", settings)
    fs = np.asarray(settings.full_scale, dtype=float)
    truth = new.loads  # scored on the noise-free outputs of every pose: simulator truth

    def worst(m):
        f = m.decouple(new.truth - m.zero, rotate=False, exact=True)
        return float((np.sqrt(((f - truth) ** 2).mean(axis=0)) / fs).max())

    import fsdecouple.fitting.fit as fitting

    with pytest.MonkeyPatch.context() as mp:  # scored on the exact path: no fast-path tables
        mp.setattr(fitting, "fit", functools.partial(fitting.fit, tables=False))
        fresh = fit(calib, settings, verdict=False)  # what fit without --prior writes
    prior = fit_with_prior(calib, settings, model, "old.json",
                           lambda c: fit(c, settings, verdict=False))
    return worst(model), worst(fresh), worst(prior)


SEED_RATIO = 0.7  # the most a seed's prior error may be of the old's or the fresh fit's


@pytest.mark.slow  # 3 seeds x 2 drifts, each an old fit, a fresh fit and the prior's choice
@pytest.mark.parametrize("kind", ["gain", "coupling"])
def test_with_ten_poses_the_prior_beats_a_fresh_fit_and_the_old_model(kind, tmp_path, old_models):
    """The issue's requirement, on the simulator's gain-and-offset drift and on a change of
    coupling the correction has no parameter for by name; the win must hold by two
    standard deviations of the seeds' scatter of log(ratio), not on average only.

    Over seeds 0-13 (this protocol), log(prior / other) per seed: gain vs old mean -2.40,
    sd 0.67; gain vs fresh -1.72, 0.42; coupling vs old -1.57, 0.40; coupling vs fresh
    -1.40, 0.50; the largest of all 56 -0.72 (ratio 0.49).  Every comparison's mean + 2 sd
    is below log(0.7) = -0.36 (-0.40 at worst), so each seed is held to SEED_RATIO = 0.7,
    the population's two-sd win, besides the seeds' own mean + 2 sd below 0 (seeds 0-2:
    -0.37 at worst; seeds 0-4 gave -0.44, at 5/3 of the CPU).
    """
    e = np.array([_errors(seed, kind, tmp_path, old_models) for seed in range(3)])
    for other in (0, 1):  # old, fresh
        ratio = np.log(e[:, 2] / e[:, other])
        assert (ratio < np.log(SEED_RATIO)).all(), (kind, other, e)
        assert ratio.mean() + 2 * ratio.std(ddof=1) < 0, (kind, other, e)


@pytest.mark.slow  # a whole prior fit: its lambda grid over held-out folds
def test_one_output_per_component_leans_on_prior_rows(tmp_path):
    # no matrix P to correct (a six-output rig): lambda copies of the new rows with the old
    # model's loads, lambda and a fresh fit scored held out on the same folds
    rig = write_rig(tmp_path / "rig")[0]
    init_config(rig, tmp_path / "rig.yaml")
    settings = load_config(tmp_path / "rig.yaml")
    calib = load_calibration(rig, settings)
    model = fit(calib, settings, verdict=False)
    assert model.projection is None
    choice = choose_prior(calib, settings, model, "old.json", folds=4, copies=(0, 2))
    assert set(choice.scores) == {FRESH, "lambda = 2 prior rows per new row"}
    assert choice.scores[choice.best] == min(choice.scores.values()) and choice.lambdas is None
    assert choice.copies == (0 if choice.best == FRESH else 2)


@pytest.mark.slow  # a whole prior fit: its lambda grid over held-out folds
def test_a_model_of_another_sensor_loses_to_a_fresh_fit(old, tmp_path):
    # sensor 1's model as the prior of sensor 0 (same layout, other gauges and chi): no
    # correction of its matrix makes its chi sensor 0's, and held-out error must see it
    tmp, _, settings = old
    other_set = simulate_poses(1, 30)
    (tmp_path / "other.csv").write_text("\n".join(pose_lines(other_set)) + "\n")
    other = fit(load_calibration(tmp_path / "other.csv", settings), settings, verdict=False)
    new = simulate_poses(0, 30, noise_seed=1)
    few = PoseSet(new.loads[::5], new.samples[::5], new.truth[::5], new.railing)
    (tmp_path / "new.csv").write_text("\n".join(pose_lines(few)) + "\n")
    choice = choose_prior(load_calibration(tmp_path / "new.csv", settings), settings, other,
                          "other.json")
    assert choice.best == FRESH and choice.fresh, choice.line()
    assert "a fresh fit of the new rows" in choice.line()
