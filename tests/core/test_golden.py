"""Golden model files (tests/fixtures/golden, written by tests/fixtures/make_golden.py) keep loading."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import SAMPLE, invoke

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


@pytest.mark.parametrize("path", GOLDEN, ids=lambda p: p.name)
def test_golden_file_loads_and_decouples_like_a_fresh_fit(path, fresh):
    golden = load_model(path)  # verifies the digest and the format version
    assert json.loads(path.read_text())["format_version"] <= FORMAT_VERSION
    log = pd.read_csv(SAMPLE / "task_voltages.csv")
    u = log[["ux", "uy", "uz"]].to_numpy()
    u = u - u[:200].mean(axis=0)
    # Same data, same settings, same libsvm: the fit is deterministic, so the forces
    # agree to rounding.  1e-6 N (1e-8 of full scale) leaves room for a faster
    # evaluator of chi in a newer format; a real change of the method is far larger.
    np.testing.assert_allclose(golden.decouple(u), fresh.decouple(u), rtol=0, atol=1e-6)


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
