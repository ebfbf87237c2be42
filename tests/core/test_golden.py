"""Golden model files (tests/fixtures/golden, written by tests/fixtures/make_golden.py) keep loading."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import SAMPLE, assert_decouples_by_its_own_numbers, assert_refit_close, invoke

from fsdecouple import load_calibration, load_config, load_model
from fsdecouple.core import modelfile as model_module
from fsdecouple.core.modelfile import FORMAT_VERSION, save_model
from fsdecouple.fitting.fit import fit

GOLDEN = sorted((Path(__file__).parents[1] / "fixtures" / "golden").glob("model-v*.json"))


@pytest.fixture(scope="module")
def fresh():
    # the golden files were written before `extrapolation`, so they read as kernel models
    settings = load_config(extrapolation="kernel")
    return fit(load_calibration(SAMPLE / "calibration", settings), settings)


def test_there_is_a_golden_file_of_the_current_version():
    assert any(p.name == f"model-v{FORMAT_VERSION}.json" for p in GOLDEN)


def _task_outputs():
    """The sample's combined-load log, zero-corrected by its first 200 rows (3000 x 3)."""
    u = pd.read_csv(SAMPLE / "task_voltages.csv")[["ux", "uy", "uz"]].to_numpy()
    return u - u[:200].mean(axis=0)


@pytest.mark.parametrize("path", GOLDEN, ids=lambda p: p.name)
@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_golden_file_loads_and_decouples_by_its_own_numbers(path):
    """The stored model, not a re-fit: the same on every machine to rounding (conftest.py)."""
    assert json.loads(path.read_text())["format_version"] <= FORMAT_VERSION
    assert_decouples_by_its_own_numbers(path, _task_outputs())


@pytest.mark.parametrize("path", GOLDEN, ids=lambda p: p.name)
@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_a_fresh_fit_decouples_like_the_golden_file_within_the_noise(path, fresh):
    """Same data and settings, fitted today on this machine: within REFIT_MAX / REFIT_RMS
    of full scale (conftest.py says why a re-fit is not compared to rounding)."""
    assert_refit_close(load_model(path), fresh, _task_outputs())


@pytest.mark.parametrize("path", GOLDEN, ids=lambda p: p.name)
def test_golden_file_through_the_cli(path, tmp_path):
    assert "chi_zy" in invoke(["show", path]).stdout
    out = tmp_path / "f.csv"
    invoke(["apply", path, SAMPLE / "task_voltages.csv", "-o", out, "--tare", "200"])
    assert len(pd.read_csv(out)) == 3000


def test_an_older_version_still_loads(monkeypatch):
    """What a v1 file meets once the format moves on: it is read, not refused."""
    monkeypatch.setattr(model_module, "FORMAT_VERSION", FORMAT_VERSION + 1)
    for path in GOLDEN:
        load_model(path)


def _beyond(model, u):
    """``u`` with every tenth row moved 0.4-0.8 spans beyond the calibrated range (past
    the tables, into the tangents), a NaN row and an infinite one."""
    r = model.calibrated_range
    u = np.array(u, dtype=float)
    rows = np.arange(0, len(u), 10)
    sign = np.where(rows % 20 == 0, 1.0, -1.0)[:, None]
    u[rows] = np.where(sign > 0, r[:, 1], r[:, 0]) + sign * np.linspace(0.4, 0.8, len(rows))[:, None] \
        * (r[:, 1] - r[:, 0])
    u[3, 1], u[5, 0] = np.nan, np.inf
    return u


@pytest.mark.parametrize("refine", [None, 2])
@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_every_evaluator_of_a_fitted_model_is_eq11_of_its_file(sample_model, refine):
    """Tangent extrapolation (the default of new fits) beyond the range, refinement, NaN."""
    model = load_model(sample_model)
    assert model.settings.extrapolation == "tangent"
    assert_decouples_by_its_own_numbers(sample_model, _beyond(model, _task_outputs()), refine,
                                        header=refine is None)


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_every_evaluator_of_a_joint_fit_with_own_load_chi_is_eq11_of_its_file(rig_model, tmp_path):
    path = tmp_path / "rig.json"
    save_model(rig_model, path)
    assert rig_model.own and rig_model.fast_decoupler() is not None
    r = rig_model.calibrated_range
    u = np.random.default_rng(3).uniform(r[:, 0], r[:, 1], (400, rig_model.n_outputs))
    for refine in (None, 1):
        assert_decouples_by_its_own_numbers(path, _beyond(rig_model, u), refine)


def test_every_evaluator_of_the_six_axis_golden_file_is_eq11_of_its_file():
    path = Path(__file__).parents[1] / "fixtures" / "golden" / "six-axis-v3.json"
    model = load_model(path)
    r = model.calibrated_range
    u = np.random.default_rng(4).uniform(r[:, 0], r[:, 1], (300, 6))
    assert_decouples_by_its_own_numbers(path, _beyond(model, u), refine=1)
