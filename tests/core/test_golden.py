"""Golden model files (tests/fixtures/golden, written by tests/fixtures/make_golden.py) keep loading."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
from conftest import SAMPLE, assert_decouples_by_its_own_numbers, assert_refit_close, invoke

from fsdecouple import load_calibration, load_config, load_model
from fsdecouple.core import modelfile as model_module
from fsdecouple.core.modelfile import FORMAT_VERSION
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
def test_golden_file_loads_and_decouples_by_its_own_numbers(path):
    """The stored model, not a re-fit: the same on every machine to rounding (conftest.py)."""
    assert json.loads(path.read_text())["format_version"] <= FORMAT_VERSION
    assert_decouples_by_its_own_numbers(path, _task_outputs())


@pytest.mark.parametrize("path", GOLDEN, ids=lambda p: p.name)
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
