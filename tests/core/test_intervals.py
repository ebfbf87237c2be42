"""Conformal intervals: the quantile, the noise model's scales, and the checks."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

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
