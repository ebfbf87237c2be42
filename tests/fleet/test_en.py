"""E_n between two calibrations: recomputed by hand from the model files' step data."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from conftest import invoke

from fsdecouple import load_model, save_model
from fsdecouple.evaluation.calibrate import fit as calibrate
from fsdecouple.fleet.drift import compare
from fsdecouple.fleet.en import en_figures


def _scaled(calib, factor: float):
    """The same calibration with every output ``factor`` times larger (zero-corrected and raw)."""
    pts = calib.points.copy()
    for c in ("ux", "uy", "uz", "ux_raw", "uy_raw", "uz_raw"):
        pts[c] = pts[c] * factor
    return replace(calib, points=pts)


@pytest.fixture(scope="module")
def pair(calib, settings, sim_model_file):
    # the first: `fsdecouple fit` of the same set (conftest's, once a session), as a file holds it
    return load_model(sim_model_file), calibrate(_scaled(calib, 1.01), settings)


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_en_is_the_difference_of_both_models_on_the_same_outputs_over_both_us(pair):
    a, b = pair
    got, why = en_figures(a, b)
    assert why is None
    for i, axis in enumerate("xyz"):
        worst = 0.0
        for own, other in ((a, b), (b, a)):
            st, ot = own.report.certificate["steps"][axis], other.report.certificate["steps"][axis]
            for load, outputs, u_own in zip(st["load"], st["outputs"], st["U"], strict=True):
                fa = a.decouple(np.array([outputs]), rotate=False, exact=True)[0, i]
                fb = b.decouple(np.array([outputs]), rotate=False, exact=True)[0, i]
                # the other model's U at this load: its steps share the load grid here
                u_other = ot["U"][ot["load"].index(load)]
                en = (fa - fb) / np.hypot(u_own, u_other)
                worst = max(worst, abs(en))
        assert got["en"][axis] == pytest.approx(worst, rel=1e-9)


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_outputs_one_percent_larger_give_en_above_one_on_every_component(pair):
    a, b = pair
    got, _ = en_figures(a, b)
    # B decouples A's step means 1 % low: 1 N at 100 N against U of 0.2-0.5 N (k = 2)
    assert all(v > 1.0 for v in got["en"].values()), got["en"]
    same, _ = en_figures(a, a)
    assert all(v == 0.0 for v in same["en"].values())


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_compare_gates_on_en_and_an_old_model_falls_back_with_a_note(pair, tmp_path):
    a, b = pair
    pa, pb = tmp_path / "a.json", tmp_path / "b.json"
    save_model(a, pa)
    save_model(b, pb)
    out = invoke(["compare", pa, pb, "--json"], 1).stdout
    doc = json.loads(out)
    assert doc["passed"] is False and set(doc["en"]) == {"x", "y", "z"}
    assert min(doc["en"].values()) > 1.0
    invoke(["compare", pa, pa], 0)
    old = replace(a, report=replace(a.report, certificate=None))
    doc = compare(old, b)
    assert doc["en"] is None and "no certificate data" in doc["en_note"]
    assert doc["passed"] is None  # neither E_n nor --max-drift: nothing to gate on
    assert compare(old, b, max_drift=0.5)["passed"] is False  # the fixed threshold stays


def test_an_uncertainty_whose_square_underflows_gives_finite_en(sim_model_file, tmp_path):
    """U = 1e-200 passes the load-time check (U > 0), but U^2 underflows to 0: E_n was
    0/0 (NaN) or x/0, and `compare --json` a traceback. sqrt(U_A^2 + U_B^2) is taken
    as hypot(U_A, U_B), which does not underflow."""
    from fsdecouple.core.modelfile import content_digest

    doc = json.loads(sim_model_file.read_text())
    for steps in doc["report"]["certificate"]["steps"].values():
        steps["U"] = [1e-200] * len(steps["U"])
    doc["integrity"]["digest"] = content_digest(doc)
    edited = tmp_path / "tiny-u.json"
    edited.write_text(json.dumps(doc))
    r = invoke(["compare", edited, edited, "--json"])  # the same model: every F_A - F_B = 0
    out = json.loads(r.stdout)
    assert out["passed"] is True and out["en"] == {"x": 0.0, "y": 0.0, "z": 0.0}
    assert all(s["U_old"] == 1e-200 and s["en"] == 0.0 for s in out["en_steps"])
