"""libsvm's settings shown with the units they are in: the outputs' own, or full scale."""

from __future__ import annotations

from dataclasses import replace

import pytest
from conftest import SAMPLE

from fsdecouple import load_calibration, load_config, load_model
from fsdecouple.reporting.console import fit_tables
from fsdecouple.reporting.tune_table import tune_table


def _chi_title(model) -> str:
    return next(t.title for t in fit_tables(model) if t.title.startswith("Corrected coupling"))


def test_the_chi_tables_svr_settings_name_their_unit(sample_model):
    """'eps=0.0001 tol=...' said nothing of the unit: volts for V data, fractions of full
    scale for mV and counts (scaling: full_scale)."""
    model = load_model(sample_model)
    assert "eps-SVR in V, gamma=0.5 C=1000 eps=0.0001 tol=" in _chi_title(model)
    scaled = replace(model, settings=replace(model.settings, scaling="full_scale"))
    assert "eps-SVR in F.S., gamma=0.5 C=1000 eps=0.0001 tol=" in _chi_title(scaled)


def _record(candidate0):
    rms = {"x": 0.1, "y": 0.1, "z": 0.1}
    cands = [{**candidate0, "table2": True, "rms": rms, "figure": 0.001, "clearly_better": False},
             {"gamma": 2.0, "C": 10.0, "epsilon": 2e-4, "scaling": "full_scale", "table2": False,
              "tolerance": 1e-5, "rms": rms, "figure": 0.0009, "clearly_better": True}]
    return {"candidates": cands, "chosen": 1, "noise": 4e-4, "protocol": "repetitions",
            "rounds": 3, "refine": 0}


def _units_column(table) -> list[str]:
    col = next(c for c in table.columns if c.header == "units")
    return list(col._cells)


def test_the_tune_tables_candidate_0_is_named_as_what_it_is():
    """Candidate 0 was 'Table 2, as configured' whatever the user had configured (--C 5),
    and its units (volts with scaling: none) were not said."""
    table2 = {"gamma": 0.5, "C": 1000.0, "epsilon": 1e-4, "scaling": "none"}
    assert _units_column(tune_table(_record(table2), "gf", "mV")) == [
        "Table 2, mV", "F.S., tol 1e-05"]
    mine = {**table2, "C": 5.0, "scaling": "full_scale"}
    assert _units_column(tune_table(_record(mine), "N"))[0] == "as configured, F.S."


@pytest.mark.slow  # two fits of the sample: over ~0.8 s of CPU
def test_tuning_that_replaces_configured_settings_says_so(monkeypatch):
    import fsdecouple.evaluation.tune as tune
    from fsdecouple.evaluation.calibrate import fit

    settings = load_config()
    record = _record({"gamma": 0.5, "C": 5.0, "epsilon": 1e-4, "scaling": "none"})
    monkeypatch.setattr(tune, "tune_settings", lambda calib, s, **_: (s, record))
    calib = load_calibration(SAMPLE / "calibration", settings)
    mine = replace(settings, svr=replace(settings.svr, C=5.0, tolerance=1e-3))
    model = fit(calib, mine, tune=True, verdict=False)
    said = [w for w in model.warnings if w.startswith("tuning replaced the configured SVR settings")]
    assert said == ["tuning replaced the configured SVR settings (C=5, epsilon=0.0001, gamma=0.5: "
                    "candidate 0) by gamma=2 C=10 epsilon=0.0002 (full scale), clearly better "
                    "on held-out points; fit without tuning keeps them"]
    table2 = replace(settings, svr=replace(settings.svr, tolerance=1e-3))  # Table 2: nothing to say
    assert not any("tuning replaced" in w for w in fit(calib, table2, tune=True, verdict=False).warnings)
