"""Conformal intervals: the quantile, the noise model's scales, and the checks."""

from __future__ import annotations

import math
import re
from dataclasses import replace

import numpy as np
import pytest
from conftest import SAMPLE, assert_one_line_error, invoke

from fsdecouple.core.intervals import (
    check_coverage,
    half_widths,
    interval_calibration,
    interval_names,
    with_intervals,
)
from fsdecouple.errors import InputError


def _with_scores(model, scores, sigma=(1.0, 2.0, 3.0)):
    cal = {"scores": list(scores),
           "components": {a: {"sigma": s, "scores": None} for a, s in zip("xyz", sigma, strict=True)}}
    return replace(model, report=replace(model.report, certificate={"interval": cal}))


def test_half_width_is_the_conformal_quantile_times_sigma(model):
    m = _with_scores(model, np.arange(1.0, 20.0))  # n = 19 scores: 1, 2, ..., 19
    # split conformal: the ceil((n + 1) P)-th smallest score; P = 0.9 -> the 18th
    assert half_widths(m, 0.9) == pytest.approx([18.0, 36.0, 54.0])
    assert half_widths(m, 0.5) == pytest.approx([10.0, 20.0, 30.0])  # ceil(10) = 10th
    with pytest.raises(InputError, match="up to P = 0.950"):
        half_widths(m, 0.96)  # ceil(19.2) = 20 > 19: no score is large enough


def test_bounds_without_outputs_are_symmetric(model):
    m = _with_scores(model, np.arange(1.0, 20.0))
    f = np.array([[1.0, -2.0, 3.0], [0.0, 0.0, 0.0]])
    out = with_intervals(m, f, 0.5)
    assert out[:, :3].tolist() == f.tolist()
    assert out[:, 3::2] == pytest.approx(f - [10.0, 20.0, 30.0])
    assert out[:, 4::2] == pytest.approx(f + [10.0, 20.0, 30.0])
    assert interval_names(("fx", "fy")) == ("fx_lo", "fx_hi", "fy_lo", "fy_hi")


def test_scores_are_residuals_over_the_held_out_sigma_and_rows_get_the_tared_sigma():
    rng = np.random.default_rng(0)
    true = rng.normal(size=(50, 2))
    pred = true + rng.normal(scale=0.1, size=(50, 2))
    cal = interval_calibration(true, pred, ("x", "y"), np.array([0.1, np.nan]), zeros=1.0,
                               repetitions=6, trained=4.0)
    s, m, n, nt, comps = 0.1, 1.0, 6, 4.0, 2
    held = s * math.sqrt((1 + 1 / m) * (1 + comps / nt))  # zero reading, fold's model terms
    row = s * math.sqrt(1 + comps * (1 + 1 / m) / n)  # a tared row, the final model's terms
    assert cal["components"]["x"]["sigma"] == pytest.approx(row)
    assert cal["scores"] == pytest.approx(sorted(np.abs(pred[:, 0] - true[:, 0]) / held))
    # no noise figure (one repetition): raw residuals of its own
    assert cal["components"]["y"] == {"sigma": 1.0,
                                      "scores": sorted(np.abs(pred[:, 1] - true[:, 1]).tolist())}


@pytest.mark.parametrize("bad", [1.5, 0.0, 1.0, -0.1, True, "0.9"])
def test_coverage_must_lie_between_0_and_1(bad):
    with pytest.raises(InputError, match="between 0 and 1"):
        check_coverage(bad)


def test_a_model_without_residuals_refuses_intervals(model):
    with pytest.raises(InputError, match="no held-out residuals"):
        half_widths(replace(model, report=replace(model.report, certificate=None)), 0.9)


def test_a_model_file_with_a_broken_certificate_block_is_refused(model):
    from fsdecouple.core.modelfile import content_digest, model_from_dict, model_to_dict
    from fsdecouple.errors import ModelFileError

    doc = model_to_dict(replace(model, report=replace(model.report, certificate={"steps": {}})))
    doc["integrity"]["digest"] = content_digest(doc)  # digest-valid, so only the shape is wrong
    with pytest.raises(ModelFileError, match="certificate needs steps"):
        model_from_dict(doc, "m.json")


def _edited(path, tmp_path, edit):
    """The model file at ``path`` with ``edit(doc)`` applied and its digest recomputed."""
    import json

    from fsdecouple.core.modelfile import content_digest

    doc = json.loads(path.read_text())
    edit(doc["report"]["certificate"])
    doc["integrity"]["digest"] = content_digest(doc)
    out = tmp_path / "edited.json"
    out.write_text(json.dumps(doc))
    return out


def _scores(cert, a="x"):
    c = cert["interval"]["components"][a]
    return c["scores"] if c["scores"] is not None else cert["interval"]["scores"]


@pytest.mark.parametrize("edit, needle", [
    (lambda c: _scores(c).__setitem__(0, -5.0), "held-out score -5.0"),  # lo > hi on every row
    (lambda c: _scores(c).reverse(), "ascending"),  # the quantile read the wrong score
    (lambda c: c["interval"]["components"]["x"].__setitem__("sigma", 0.0), "sigma = 0.0"),
    (lambda c: c["interval"]["components"]["x"].__setitem__("sigma", 1e300), "sigma = 1e+300"),
    (lambda c: _scores(c).__setitem__(-1, 1e308), "times sigma"),
    (lambda c: c["steps"]["y"]["U"].__setitem__(0, 0.0), "y: U = 0.0"),  # E_n of x/0
    (lambda c: c["steps"]["z"]["model_error"].__setitem__(1, 1e300), "model_error = 1e+300"),
    (lambda c: c["steps"]["z"]["model_error"].__setitem__(1, -1.0), "model_error = -1.0"),
])
def test_edited_interval_and_step_data_are_refused_at_load_even_with_a_digest(
        sample_model, tmp_path, edit, needle):
    """The digest says the file is as written, not that its numbers can be (issue 34)."""
    from fsdecouple.core.modelfile import load_model
    from fsdecouple.errors import ModelFileError

    load_model(_edited(sample_model, tmp_path, lambda c: None))  # the untouched file loads
    with pytest.raises(ModelFileError, match=re.escape(needle)):
        load_model(_edited(sample_model, tmp_path, edit))


@pytest.mark.parametrize("args, edit", [
    (["compare", "{m}", "{e}", "--json"], lambda c: c["steps"]["x"]["U"].__setitem__(2, 0.0)),
    (["certificate", "{e}", str(SAMPLE / "calibration"), "--json"],
     lambda c: c["steps"]["x"]["model_error"].__setitem__(0, 1e300)),
])
def test_compare_and_certificate_json_refuse_an_edited_model_in_one_line(
        sample_model, tmp_path, args, edit):
    """Issue 34: E_n of x/0 and a model error of 1e300 were JSON ValueError tracebacks."""

    e = _edited(sample_model, tmp_path, edit)
    r = invoke([a.format(m=sample_model, e=e) for a in args], 2)
    assert_one_line_error(r, str(e), "refit it")
