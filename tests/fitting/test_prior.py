"""``fit NEW --prior OLD.json`` (issue 32 item 7): lambda chosen by held-out error among
whole numbers of prior rows per new row, 0 (a fresh fit) among them (fitting/prior.py)."""

from __future__ import annotations

import numpy as np
from conftest import assert_one_line_error, invoke

from fsdecouple.config import load_config
from fsdecouple.core.modelfile import load_model
from fsdecouple.data.calibration import load_calibration
from fsdecouple.data.init_config import init_config
from fsdecouple.fitting.prior import LAMBDAS, choose_lambda, with_prior, zero_shift
from fsdecouple.sim.poses import pose_lines, simulate_poses
from fsdecouple.sim.rig import write_rig


def test_prior_rows_carry_the_old_models_loads_and_one_zero(tmp_path):
    path = tmp_path / "poses.csv"
    path.write_text("\n".join(pose_lines(simulate_poses(0, 30))) + "\n")
    init_config(path, tmp_path / "cfg.yaml")
    invoke(["fit", path, "-c", tmp_path / "cfg.yaml", "-o", tmp_path / "old.json", "--no-verdict"])
    old = load_model(tmp_path / "old.json")
    calib = load_calibration(path, load_config(tmp_path / "cfg.yaml"))
    out = with_prior(calib, old, 2)
    n = len(calib.points)
    assert len(out.points) == 3 * n
    u = out.points[list(calib.layout.outputs)].to_numpy()
    np.testing.assert_array_equal(u[n:2 * n], u[:n])
    np.testing.assert_allclose(out.points[list(calib.layout.loads)].to_numpy()[n:2 * n],
                               old.decouple(u[:n], rotate=False, exact=True), atol=1e-9)
    # the old model's own calibration: its zero needs (almost) no shift
    delta = zero_shift(old, calib.voltages, calib.forces)
    assert np.abs(delta).max() < 1.0  # counts, of readings ~500


def test_fit_with_a_prior_says_which_lambda_and_why(tmp_path):
    path = tmp_path / "poses.csv"
    path.write_text("\n".join(pose_lines(simulate_poses(0, 30))) + "\n")
    init_config(path, tmp_path / "cfg.yaml")
    invoke(["fit", path, "-c", tmp_path / "cfg.yaml", "-o", tmp_path / "old.json", "--no-verdict"])
    new = tmp_path / "new.csv"
    new.write_text("\n".join(pose_lines(simulate_poses(0, 30, drift=0.01, noise_seed=1))) + "\n")
    r = invoke(["fit", new, "-c", tmp_path / "cfg.yaml", "-o", tmp_path / "new.json",
                "--prior", tmp_path / "old.json", "--no-verdict"])
    assert "prior model" in r.stderr and "chosen by held-out worst component's RMS error" in r.stderr
    settings = load_config(tmp_path / "cfg.yaml")
    choice = choose_lambda(load_calibration(new, settings), settings,
                           load_model(tmp_path / "old.json"), "old.json")
    assert set(choice.scores) == set(LAMBDAS) and choice.scores[choice.lam] == min(choice.scores.values())


def test_a_prior_of_another_sensor_is_refused(tmp_path):
    path = tmp_path / "poses.csv"
    path.write_text("\n".join(pose_lines(simulate_poses(0, 10))) + "\n")
    init_config(path, tmp_path / "cfg.yaml")
    rig = write_rig(tmp_path / "rig")[0]
    init_config(rig, tmp_path / "rig.yaml")
    invoke(["fit", rig, "-c", tmp_path / "rig.yaml", "-o", tmp_path / "rig.json", "--no-verdict"])
    r = invoke(["fit", path, "-c", tmp_path / "cfg.yaml", "-o", tmp_path / "m.json",
                "--prior", tmp_path / "rig.json"], code=2)
    assert_one_line_error(r, "--prior", "same sensor and layout")
    assert not (tmp_path / "m.json").exists()
