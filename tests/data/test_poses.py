"""Pose logs (issue 22): timestamped samples of one static load, averaged per load; their
scatter is the noise sigma the joint fit takes as its epsilon (data/poses.py)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from fsdecouple.config import SVRSettings, load_config
from fsdecouple.data.calibration import load_calibration
from fsdecouple.data.init_config import init_config
from fsdecouple.fitting.joint import JOINT_C, joint_svr
from fsdecouple.fitting.linear import fit_omega
from fsdecouple.sim.rig import COMPONENTS, FULL_SCALE, rig_rows

SAMPLES, SIGMA = 12, 2e-3  # samples per pose; their noise, a fraction of full scale


def pose_log(tmp_path: Path, seed: int = 0, stamp: bool = True):
    """A rig's loads held while a logger samples the readings: (path, loads, samples)."""
    f, r = rig_rows(seed)
    rng = np.random.default_rng(seed + 100)
    samples = np.repeat(r, SAMPLES, axis=0) + rng.normal(0, SIGMA, (len(r) * SAMPLES, 6)) * FULL_SCALE
    loads = np.repeat(f, SAMPLES, axis=0)
    path = tmp_path / "poses.csv"
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([*(["timestamp"] if stamp else []), *COMPONENTS,
                    *(f"known_{c}" for c in COMPONENTS)])
        for i, (u, load) in enumerate(zip(samples, loads, strict=True)):
            w.writerow([*([f"2026-01-01T00:{i // 60:02d}:{i % 60:02d}"] if stamp else []),
                        *(repr(float(v)) for v in u), *(repr(float(v)) for v in load)])
    return path, f, samples


def read(tmp_path, **kw):
    path, f, samples = pose_log(tmp_path, **kw)
    init_config(path, tmp_path / "cfg.yaml")
    settings = load_config(tmp_path / "cfg.yaml")
    return load_calibration(path, settings), settings, f, samples


def test_samples_of_one_load_become_one_point_named_by_its_first_line(tmp_path):
    calib, settings, f, samples = read(tmp_path)
    pts = calib.points
    assert len(pts) == len(f)
    np.testing.assert_array_equal(pts["row"].to_numpy(), 2 + SAMPLES * np.arange(len(f)))
    raw = pts[[f"{o}_raw" for o in settings.layout.outputs]].to_numpy()
    means = samples.reshape(len(f), SAMPLES, 6).mean(axis=1)
    np.testing.assert_allclose(raw, means, rtol=0, atol=1e-12 * FULL_SCALE.max())
    np.testing.assert_array_equal(calib.forces, f)
    note = next(w for w in calib.warnings if "timestamped samples" in w)
    assert f"{len(f) * SAMPLES} timestamped samples of {len(f)} static loads (lines 2-13, " in note


def test_their_scatter_is_the_noise_sigma_of_each_average(tmp_path):
    calib, _, _, _ = read(tmp_path)
    # pooled over 60 poses x 11 degrees of freedom: the estimate's relative scatter is
    # 1 / sqrt(2 x 660) = 3 %; over seeds 0-19 the largest of the six outputs' was 7 %
    want = SIGMA * FULL_SCALE / np.sqrt(SAMPLES)
    np.testing.assert_allclose(calib.noise, want, rtol=0.12)


def test_a_file_without_a_timestamp_is_read_row_by_row(tmp_path):
    calib, _, f, _ = read(tmp_path, stamp=False)
    assert len(calib.points) == len(f) * SAMPLES and calib.noise is None


def test_the_joint_fit_takes_the_pose_sigma_as_its_epsilon(tmp_path, monkeypatch):
    import fsdecouple.fitting.fit as fit_module

    calib, settings, _, _ = read(tmp_path)
    seen = {}

    def spy(svr, f, u, a, sigma=None):
        seen[a] = sigma
        return joint_svr(svr, f, u, a, sigma)

    monkeypatch.setattr(fit_module, "joint_svr", spy)
    fit_module.fit(calib, settings, tables=False)
    # in the fit's units: each output over its full-scale output |k| F_FS (scaling: full_scale)
    assert settings.scaling == "full_scale"
    scale = np.abs(fit_omega(calib.points, settings.layout).k) * FULL_SCALE
    np.testing.assert_allclose([seen[a] for a in range(6)], calib.noise / scale, rtol=1e-12)
    s = joint_svr(SVRSettings(), np.ones((3, 1)), np.ones((3, 1)), 0, sigma=0.01)
    assert s.C == JOINT_C and s.epsilon == pytest.approx(0.01)


def test_a_sweep_file_with_a_date_column_is_not_a_pose_log(tmp_path):
    """A lab's sweeps 0 -> L -> 0 with a Date column: the zero row ending one sweep and the
    one starting the next were averaged into one point as a 'pose' of two samples, which
    changed the fit (held-out gamma 0.15 % against 0.31 % without the column)."""
    rng = np.random.default_rng(3)
    levels = [0, 50, 100, 100, 50, 0]  # the peak held twice at the turn, too
    path = tmp_path / "cal.csv"
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["Date", "Fx [N]", "Fy [N]", "Fz [N]", "ch0", "ch1", "ch2"])
        for axis in range(3):
            for level in levels:
                f = np.zeros(3)
                f[axis] = level
                u = f / 100 + 0.01 * f[[1, 2, 0]] / 100 + rng.normal(0, 1e-5, 3)
                w.writerow(["2024-03-05", *map(repr, f.tolist()), *map(repr, u.tolist())])
    init_config(path, tmp_path / "cfg.yaml")
    calib = load_calibration(path, load_config(tmp_path / "cfg.yaml"))
    assert len(calib.points) == 3 * len(levels)
    assert not any("timestamped samples" in w for w in calib.warnings)
