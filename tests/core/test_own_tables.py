"""The own-load chi_aa of a joint fit (issue 22) in the table path: verified tables on
their input's grid, and fast forces that keep the promise against the exact kernel sums."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from fsdecouple.core.decouple import PROMISE, usable
from fsdecouple.core.modelfile import load_model, model_from_dict, model_to_dict, save_model
from fsdecouple.core.surrogate import TOLERANCE, check_points, spot_check
from fsdecouple.errors import ModelFileError


def voltages(model, n, lo_frac=0.0, hi_frac=1.0, seed=0):
    lo, hi = model.calibrated_range.T
    return lo + (hi - lo) * np.random.default_rng(seed).uniform(lo_frac, hi_frac, (n, len(lo)))


def test_every_own_chi_has_a_verified_table_on_its_inputs_grid(rig_model):
    model = rig_model
    u_fs = model.full_scale_output
    assert sorted(model.own) == sorted(f"{c}:{c}" for c in model.layout.labels)
    for c in model.own.values():
        a = c.output_axis
        s = c.surrogate
        assert s is not None and usable(s, u_fs[a])
        assert s.max_error <= TOLERANCE * u_fs.min() * 1.0001  # fit builds to the pair's tolerance
        # re-measured here on the full check grid, against the kernel sum
        x = check_points(s.lo, s.hi, s.intervals, s.checks_per_interval)
        inside = s.covers(x)
        assert np.abs(s(x[inside]) - c(x[inside])).max() <= s.max_error * (1 + 1e-6)
        # the grid every chi fed by input a uses: one index per input value
        fed = {(d.surrogate.lo, d.surrogate.hi, d.surrogate.intervals)
               for d in model.chi.values() if d.input_axis == a}
        assert fed == {(s.lo, s.hi, s.intervals)}
        assert spot_check(c, s)[0] <= s.max_error * 4
    assert set(model.report.surrogate_max_error) == {*model.chi, *model.own}


@pytest.mark.parametrize("refine", [0, 1, 2])
def test_fast_forces_with_own_chi_keep_the_promise_against_the_exact_path(rig_model, refine):
    model = rig_model
    assert model.fast_decoupler() is not None
    u = voltages(model, 5_000, -0.1, 1.1)
    fs = np.asarray(model.settings.full_scale)
    exact = model.decouple(u, exact=True, refine=refine)
    covered = np.empty(len(u), dtype=bool)
    fast = model.fast_decoupler().decouple(u, refine=refine, covered=covered)
    assert covered.all() and np.isfinite(exact).all()
    # an own table error e is e / k in force, as a cross chi's: the same promise
    assert (np.abs(fast - exact) / fs).max() <= PROMISE
    # and the own-load term is there: without it the forces move by its size
    bare = replace(model, own={})
    moved = np.abs(bare.decouple(u, exact=True, refine=refine) - exact) / fs
    assert moved.max() > 1e3 * PROMISE


@pytest.mark.parametrize("refine", [0, 2])
def test_one_vector_path_with_own_chi_is_bit_identical_to_the_compiled_one(rig_model, refine):
    tables = rig_model.fast_decoupler()
    u = voltages(rig_model, 300, -0.1, 1.1, seed=1)
    u[7, 2] = np.nan  # NaN and far beyond the tables: the exact path on both
    u[8, 4] = 1e3 * abs(u[:, 4]).max()
    one = tables.one(rotate=False, refine=refine)
    covered = np.empty(len(u), dtype=bool)
    block = tables.decouple(u, rotate=False, refine=refine, covered=covered)
    assert np.array_equal(np.array([one(*v) for v in u.tolist()]), block, equal_nan=True)
    assert not covered[7] and not covered[8] and covered.sum() == len(u) - 2
    np.testing.assert_array_equal(block[8], rig_model.decouple(u[8:9], exact=True, refine=refine)[0])


def test_own_tables_round_trip_and_an_edited_one_is_refused(rig_model, tmp_path):
    path = tmp_path / "rig.json"
    save_model(rig_model, path)
    back = load_model(path)
    name = next(iter(back.own))
    a, b = back.own[name].surrogate, rig_model.own[name].surrogate
    assert np.array_equal(a.values, b.values) and np.array_equal(a.slopes, b.slopes)
    u = voltages(back, 500)
    np.testing.assert_array_equal(back.decouple(u), rig_model.decouple(u))
    doc = model_to_dict(back)
    s = doc["chi_own"][name]["surrogate"]
    s["values"][len(s["values"]) // 2] += 1e-3 * float(back.full_scale_output.max())
    from fsdecouple.core.modelfile import content_digest

    doc["integrity"]["digest"] = content_digest(doc)
    with pytest.raises(ModelFileError, match=f"chi '{name}': its surrogate table differs"):
        model_from_dict(doc)


def test_a_missing_own_table_leaves_the_model_to_the_exact_path(rig_model):
    name = next(iter(rig_model.own))
    own = {**rig_model.own, name: replace(rig_model.own[name], surrogate=None)}
    model = replace(rig_model, own=own)
    assert model.fast_decoupler() is None
    u = voltages(model, 50)
    np.testing.assert_array_equal(model.decouple(u), model.decouple(u, exact=True))
