"""The decoupling plan (core/plan.py): a step in the plan is evaluated by every form that
reads it, checked against eq. (11) written out from the model file (conftest.eq11_from_file),
or refused loudly by a form that has no case for it.  The C header's side is in
tests/export/test_export.py (test_a_step_added_to_the_plan_reaches_the_header)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import EXACT_TOL, TABLE_TOL, eq11_from_file

from fsdecouple import load_model
from fsdecouple.core.decouple import exact
from fsdecouple.core.plan import Couple, InputCorrection, UnknownStep
from fsdecouple.core.table_path import TableDecoupler
from fsdecouple.export.c_source import render
from fsdecouple.export.header import emulate_float, plan_export


def correction(model) -> InputCorrection:
    """An offset of a few % of each channel's span and gains 2-3 % off 1: the shape of the
    temperature terms u_i(T0) = (u_i - b_i dT) / (1 + g_i dT) at one temperature."""
    span = np.ptp(model.calibrated_range, axis=1)
    return InputCorrection(span * np.array([0.03, -0.02, 0.025]), np.array([1.02, 0.97, 1.03]))


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_an_input_correction_is_applied_by_every_form(sample_model):
    model = load_model(sample_model)
    doc = json.loads(sample_model.read_text())
    step = correction(model)
    plan = model.plan().inserted(step)
    assert isinstance(plan.steps[0], InputCorrection) and isinstance(plan.steps[1], Couple)
    r = model.calibrated_range
    u = np.random.default_rng(8).uniform(r[:, 0], r[:, 1], (500, 3))
    u[::25, 1] = r[1, 1] + 0.7 * (r[1, 1] - r[1, 0])  # beyond the tables: the exact path
    want = eq11_from_file(doc, u, correction=(step.offset, step.gain))
    fs = np.asarray(model.settings.full_scale)
    # the correction matters: a form that left it out would miss by far more than any tolerance
    assert (np.abs(eq11_from_file(doc, u) - want) / fs).max() > 1e4 * TABLE_TOL
    tables = TableDecoupler.from_plan(plan)
    one = tables.one()
    forms = {"exact": (exact(plan, u), EXACT_TOL),
             "tables": (tables.decouple(u, compiled=False), TABLE_TOL),
             "compiled": (tables.decouple(u, compiled=True), TABLE_TOL),
             "small calls": (tables.decouple(u[:5]), TABLE_TOL),
             "decoupler()": (np.array([one(*v) for v in u.tolist()]), TABLE_TOL)}
    for name, (got, tol) in forms.items():
        err = np.abs(got - want[:len(got)]) / fs
        assert err.max() <= tol, (name, err.max(axis=0))
    # the float header's emulation: within the header's own measured float bound (x2: that
    # bound is measured on the model without the correction, whose gains are near 1)
    export = plan_export(model, precision="float")
    export.plan = export.plan.inserted(step)
    u32 = u.astype(np.float32)
    want32 = eq11_from_file(doc, u32.astype(float), correction=(step.offset, step.gain))
    err = np.abs(emulate_float(export, u32) - want32) / fs
    assert err.max() <= 2 * export.float_max_error, err.max(axis=0)


class _Offset:
    """A step kind no evaluator knows (as a new term would be before its cases are written)."""

    offset = np.zeros(3)


def test_every_form_refuses_a_step_it_has_no_case_for(sample_model):
    model = load_model(sample_model)
    plan = model.plan().inserted(_Offset())
    u = np.zeros((100, 3))
    tables = TableDecoupler.from_plan(plan)
    export = plan_export(model)
    export.plan = export.plan.inserted(_Offset())
    forms = {"the exact path": lambda: exact(plan, u),
             "the table path": lambda: tables.decouple(u),
             "the one-vector path": lambda: tables.one()(0.0, 0.0, 0.0),
             "the float emulation": lambda: emulate_float(export, u.astype(np.float32)),
             "the C emitter": lambda: render(export)}
    for name, call in forms.items():
        with pytest.raises(UnknownStep, match=f"{name} has no case for a _Offset step"):
            call()


def with_temperature(model, zero=None):
    """The sample model with fitted-style temperature terms (the temperature an input after
    the outputs): offset drift 0.1 % of each span per K, gain drift 150-300 ppm/K."""
    from dataclasses import replace

    from fsdecouple.core.temperature import TemperatureTerms

    span = np.ptp(model.calibrated_range, axis=1)
    terms = TemperatureTerms(3, 25.0, 1e-3 * span * np.array([1.0, -0.8, 0.6]),
                             np.array([3e-4, -1.5e-4, 2e-4]), "degC", (15.0, 35.0))
    return replace(model, temperature=terms)


def by_hand(doc, u, t, t0, b, g, zero=None):
    """The temperature terms written out (ATI's form, docs/temperature.md), then eq. (11)
    from the file: the reference every form is checked against."""
    c = (u - b * (t[:, None] - t0)) / (1 + g * (t[:, None] - t0))
    if zero is not None:
        c = c - (zero[:-1] - b * (zero[-1] - t0)) / (1 + g * (zero[-1] - t0))
    return eq11_from_file(doc, c)


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_the_temperature_step_is_applied_by_every_form(sample_model):
    """model.decouple (tables, compiled, small calls, exact), decoupler() and the float
    emulation all apply the plan's temperature step, with and without a zero."""
    base = load_model(sample_model)
    doc = json.loads(sample_model.read_text())
    model = with_temperature(base)
    terms = model.temperature
    r = base.calibrated_range
    rng = np.random.default_rng(11)
    u = rng.uniform(r[:, 0], r[:, 1], (400, 3))
    t = rng.uniform(10.0, 40.0, 400)
    zero = np.array([*(0.02 * np.ptp(r, axis=1)), 31.0])
    fs = np.asarray(base.settings.full_scale)
    for z in (None, zero):
        want = by_hand(doc, u, t, terms.t0, terms.b, terms.g, z)
        # left out, the step would miss by far more than any tolerance
        assert (np.abs(eq11_from_file(doc, u) - want) / fs).max() > 1e4 * TABLE_TOL
        forms = {"tables": (model.decouple(u, temperature=t, zero=z, compiled=False), TABLE_TOL),
                 "compiled": (model.decouple(u, temperature=t, zero=z, compiled=True), TABLE_TOL),
                 "small": (model.decouple(u[:5], temperature=t[:5], zero=z), TABLE_TOL),
                 "exact": (model.decouple(u, temperature=t, zero=z, exact=True), EXACT_TOL)}
        for name, (got, tol) in forms.items():
            err = np.abs(got - want[:len(got)]) / fs
            assert err.max() <= tol, (name, z is not None, err.max(axis=0))
    one = model.decoupler()
    got = np.array([one(*v, tv) for v, tv in zip(u.tolist(), t.tolist(), strict=True)])
    assert (np.abs(got - by_hand(doc, u, t, terms.t0, terms.b, terms.g)) / fs).max() <= TABLE_TOL
    export = plan_export(model, precision="float")
    assert export.m == 4  # one more input: the temperature
    x32 = np.column_stack([u, t]).astype(np.float32)
    want32 = by_hand(doc, x32[:, :3].astype(float), x32[:, 3].astype(float), terms.t0, terms.b, terms.g)
    err = np.abs(emulate_float(export, x32) - want32) / fs
    assert err.max() <= export.float_max_error, err.max(axis=0)


@pytest.mark.slow  # a joint fit of eight gauges (~5 s)
def test_every_form_of_an_m_over_n_model_is_eq11_of_its_file(tmp_path):
    """M > N outputs (fitting/gauges.py): the projection v = P u is a step of the plan, and
    an input correction goes on the raw outputs before it, in every form."""
    from conftest import assert_decouples_by_its_own_numbers

    from fsdecouple import load_calibration, load_config, save_model
    from fsdecouple.data.init_config import init_config
    from fsdecouple.fitting.fit import fit
    from fsdecouple.sim.rig import write_rig

    path = write_rig(tmp_path, seed=0, kind="lever-arm", gauges=8)[0]
    init_config(path, tmp_path / "cfg.yaml")
    settings = load_config(tmp_path / "cfg.yaml")
    model = fit(load_calibration(path, settings), settings)
    assert model.projection is not None and model.fast_decoupler() is not None
    file = tmp_path / "m.json"
    save_model(model, file)
    r = model.calibrated_range  # of v = P u: outputs u = P^+ v spanning it
    v = np.random.default_rng(6).uniform(r[:, 0], r[:, 1], (300, model.n_components))
    u = v @ np.linalg.pinv(model.projection).T
    assert_decouples_by_its_own_numbers(file, u)
    gain = 1.0 + 0.02 * np.cos(np.arange(model.n_outputs))
    step = InputCorrection(0.01 * np.abs(u).max(axis=0), gain)
    plan = model.plan().inserted(step)
    assert isinstance(plan.steps[0], InputCorrection)
    want = eq11_from_file(json.loads(file.read_text()), u, correction=(step.offset, step.gain))
    tables = TableDecoupler.from_plan(plan)
    one = tables.one()
    fs = np.asarray(model.settings.full_scale)
    for name, got, tol in (("exact", exact(plan, u), EXACT_TOL),
                           ("tables", tables.decouple(u), TABLE_TOL),
                           ("decoupler()", np.array([one(*x) for x in u.tolist()]), TABLE_TOL)):
        assert (np.abs(got - want) / fs).max() <= tol, name
