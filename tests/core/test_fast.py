"""The fast path: chi surrogates, the table evaluator, the single-vector call, and
apply in CSV and Parquet.  Accuracy bounds only; speed is for benchmarks/run.py."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import SAMPLE

from fsdecouple import load_calibration
from fsdecouple.axes import CHI_NAMES
from fsdecouple.core.decouple import MAX_SURROGATE_ERROR, PROMISE, usable
from fsdecouple.core.modelfile import load_model, model_from_dict, model_to_dict, save_model
from fsdecouple.core.surrogate import MAX_INTERVALS, check_points
from fsdecouple.errors import ModelFileError
from fsdecouple.fitting.fit import chi_training_data, fit
from fsdecouple.fitting.svr import predict, train
from fsdecouple.logs.apply import apply_file
from fsdecouple.logs.sinks import force_decimals

# The promise: the fast path is within 1e-9 V of the exact kernel sum for every
# chi; an output adds two chi and divides by k, so forces agree to 1e-9 / k N
# (each chi is built to 1e-10 V, which leaves the factor 2 far inside).
BOUND_V = 1e-9


def dense_points(lo, hi, n, seed):
    """Random points plus an 8192-step grid (every knot and midpoint of tables up to
    4096 intervals) in [lo, hi)."""
    rng = np.random.default_rng(seed)
    grid = lo + (hi - lo) * np.arange(8192) / 8192
    return np.concatenate([rng.uniform(lo, hi, n), grid])


def in_range_voltages(model, n, seed=0):
    r = model.calibrated_range
    return np.random.default_rng(seed).uniform(r[:, 0], r[:, 1], (n, 3))


def test_every_chi_has_a_verified_surrogate(model):
    for name, c in model.chi.items():
        s = c.surrogate
        assert s is not None, name
        assert s.max_error <= 1e-10 < PROMISE, name
        lo, hi = c.input_range
        assert s.lo < lo and s.hi > hi  # the calibrated range plus a margin


@pytest.mark.parametrize("train", [[3, 4, 5, 6], [1, 2, 5, 6], [1, 2, 3, 4]])
@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_every_cv_round_of_the_sample_data_gets_a_usable_surrogate(train, settings):
    """Round 1 once measured a NaN error (a check point whose table index rounded up
    to the end of the table), refined to 131072 intervals for 10 s and fell back to
    the exact path: cv's training rounds are the models users actually fit."""
    m = fit(load_calibration(SAMPLE / "calibration", settings).subset(train), settings)
    u_fs = np.abs(m.k) * np.asarray(settings.full_scale)  # tolerances are fractions of it
    for name, c in m.chi.items():
        assert c.surrogate.max_error <= 1e-10 * u_fs[c.output_axis], name
        assert c.surrogate.intervals < MAX_INTERVALS, name
    assert m.fast_decoupler() is not None


def test_surrogate_covers_exactly_where_its_index_is_inside(model):
    s = next(iter(model.chi.values())).surrogate
    below_hi = np.nextafter(s.hi, -np.inf) - np.arange(64) * np.spacing(s.hi)
    x = np.concatenate([below_hi, [s.lo, s.hi, np.nextafter(s.lo, -np.inf), np.nan]])
    t = (x - s.lo) * s.inv_step
    np.testing.assert_array_equal(s.covers(x), (t >= 0) & (t < s.intervals))
    np.testing.assert_array_equal(np.isnan(s(x)), ~s.covers(x))


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_surrogate_equals_kernel_sum_on_dense_points(model):
    for name, c in model.chi.items():
        s = c.surrogate
        x = dense_points(s.lo, s.hi, 200_000, seed=1)
        np.testing.assert_allclose(s(x), c(x), rtol=0, atol=BOUND_V, err_msg=name)


@pytest.mark.slow  # over ~0.8 s: the not-slow run stays under a minute
def test_surrogate_equals_libsvm_prediction(calib, model):
    """The chain surrogate -> kernel sum -> libsvm, checked end to end."""
    for name in CHI_NAMES:
        x, y = chi_training_data(calib, name)
        libsvm_model = train(x, y, model.settings.svr)  # the tolerance fit solved to (noise.py)
        c = model.chi[name]
        s = c.surrogate
        pts = dense_points(s.lo, s.hi, 20_000, seed=2)
        # beyond the calibrated range the model's chi is libsvm's prediction continued
        # along its tangent at the edge (the analytic slope, itself checked against
        # finite differences in test_extrapolation.py)
        lo, hi = c.input_range
        edge = np.clip(pts, lo, hi)
        want = predict(libsvm_model, edge) + c.kernel_slope(edge) * (pts - edge)
        np.testing.assert_allclose(s(pts), want, rtol=0, atol=BOUND_V, err_msg=name)


@pytest.mark.slow  # over ~0.6 s: the not-slow run stays under a minute
def test_the_gate_leaves_room_for_errors_between_check_points(model):
    """Checked 25x more densely than at fit time (1000 points per interval), every
    surrogate stays within the gate: the recorded error is a sample, and the gate
    (a quarter of the promise) is what allows for the part it misses."""
    for name, c in model.chi.items():
        s = c.surrogate
        x = check_points(s.lo, s.hi, s.intervals, 500)
        x = x[s.covers(x)]
        err = float(np.max(np.abs(s(x) - c(x))))
        assert err <= MAX_SURROGATE_ERROR and err <= 2 * max(s.max_error, 1e-11), name


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_fast_decouple_equals_exact_in_range(model):
    u = in_range_voltages(model, 300_000)
    fast, exact = model.decouple(u), model.decouple(u, exact=True)
    np.testing.assert_array_less(np.abs(fast - exact) * np.abs(model.k), BOUND_V)


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_fast_decouple_does_not_depend_on_blocks_threads_or_compiler(model):
    """numpy and the compiled kernel (numba) run the same operations in the same order."""
    u = in_range_voltages(model, 100_003)
    u[::101, 1] = 9.0  # outside a table: the exact path in both
    fd = model.fast_decoupler()
    ref = fd.decouple(u, workers=1, compiled=False)
    np.testing.assert_array_equal(fd.decouple(u, workers=2, block_rows=997), ref)
    for k in (0, 2):
        np.testing.assert_array_equal(fd.decouple(u, refine=k, compiled=True),
                                      fd.decouple(u, refine=k, compiled=False))
    np.testing.assert_array_equal(model.decouple(u[:5]), ref[:5])


@pytest.mark.slow  # fits the rig model when no earlier test has
def test_a_call_takes_the_compiled_kernel_by_its_chi_evaluations(model, rig_model,
                                                                    monkeypatch):
    """COMPILED_WORK counts chi evaluations (TableDecoupler.work): N (N - 1) a step for
    K + 1 steps, and an own-load chi_aa once (at the measured u). The default choice
    of ``compiled`` follows it; the spy records it and runs numpy."""
    from fsdecouple.core import table_path

    three = model.fast_decoupler()
    assert [three.work(1, k) for k in (0, 3)] == [6, 24]
    joint = rig_model.fast_decoupler()  # six axes with own-load chi (a joint fit)
    assert joint.has_own and [joint.work(1, k) for k in (0, 3)] == [30 + 6, 120 + 6]
    chosen = []
    real = table_path.TableDecoupler._couple

    def spy(self, u, workers, block_rows, covered, converged, compiled, refine):
        chosen.append(compiled)
        return real(self, u, workers, block_rows, covered, converged, False, refine)

    monkeypatch.setattr(table_path.TableDecoupler, "_couple", spy)
    monkeypatch.setattr(table_path, "COMPILED_WORK", 24 * 100)
    u = np.full((100, 3), 0.1)
    for rows, refine, expected in ((100, 0, False), (100, 3, True), (99, 3, False), (400, 0, True)):
        three.decouple(np.resize(u, (rows, 3)), refine=refine)
        assert chosen[-1] is expected, (rows, refine)


def test_small_calls_are_bit_identical_to_the_block_path(model):
    """Up to SMALL_ROWS rows go row by row (fast for one vector); same bits as a big call."""
    from fsdecouple.core.table_path import SMALL_ROWS

    u = in_range_voltages(model, 200, seed=11)
    u[::9, 2] = 7.5  # outside a table: exact in both
    u[4, 0] = np.nan
    ref = model.fast_decoupler().decouple(u, block_rows=64)
    for n in (1, 2, SMALL_ROWS, SMALL_ROWS + 1):
        for a in (0, 3, 100):
            np.testing.assert_array_equal(model.decouple(u[a:a + n]), ref[a:a + n])
    assert model.decouple(np.empty((0, 3))).shape == (0, 3)


def test_out_of_range_and_nan_use_the_exact_kernel_sum(model):
    u = in_range_voltages(model, 1000)
    s = model.chi["xy"].surrogate
    u[::7, 1] = s.hi + np.linspace(0, 2, u[::7].shape[0])  # beyond the table
    u[3::11, 0] = -50.0
    u[5, 2] = np.nan
    fast, exact = model.decouple(u), model.decouple(u, exact=True)
    bad = np.zeros(len(u), bool)
    bad[::7] = bad[3::11] = bad[5] = True
    np.testing.assert_array_equal(fast[bad], exact[bad])
    assert np.isnan(fast[5]).all() and not np.isnan(fast[~bad]).any()
    np.testing.assert_array_less(np.abs(fast[~bad] - exact[~bad]) * np.abs(model.k), BOUND_V)
    # the upper end of a table is outside it (half-open), and exact
    edge = np.array([[0.1, s.hi, -0.3]])
    np.testing.assert_array_equal(model.decouple(edge), model.decouple(edge, exact=True))


def test_single_vector_call_equals_vectorised(model):
    one = model.decoupler()
    u = in_range_voltages(model, 2000, seed=3)
    u[::50, 0] = 9.0  # outside: exact path in both
    vec = model.decouple(u)
    got = np.array([one(*row) for row in u.tolist()])
    np.testing.assert_allclose(got, vec, rtol=0, atol=1e-12)
    assert all(type(v) is float for v in one(0.1, 0.2, -0.3))
    assert np.isnan(one(float("nan"), 0.0, 0.0)).all()
    assert model.decouple_one(*u[1]) == one(*u[1])


def test_single_vector_call_with_rotation(model):
    rot = ((0.0, -1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    rotated = replace(model, settings=replace(model.settings, rotation=rot))
    u = in_range_voltages(model, 200, seed=4)
    vec = rotated.decouple(u)
    np.testing.assert_allclose(vec, model.decouple(u) @ np.asarray(rot).T, rtol=0, atol=1e-12)
    one = rotated.decoupler()
    np.testing.assert_allclose([one(*r) for r in u.tolist()], vec, rtol=0, atol=1e-12)


def test_model_without_surrogates_is_exact(model):
    bare = replace(model, chi={n: replace(c, surrogate=None) for n, c in model.chi.items()})
    assert bare.fast_decoupler() is None
    u = in_range_voltages(model, 100)
    np.testing.assert_array_equal(bare.decouple(u), model.decouple(u, exact=True))
    np.testing.assert_allclose([bare.decouple_one(*r) for r in u.tolist()],
                               model.decouple(u, exact=True), rtol=0, atol=1e-12)


def test_surrogate_round_trips_through_the_model_file(model, tmp_path):
    path = tmp_path / "m.json"
    save_model(model, path)
    doc = json.loads(path.read_text())
    for name in CHI_NAMES:
        rec = doc["chi"][name]["surrogate"]
        assert rec["kind"] == "hermite3-uniform" and rec["max_error"] <= 1e-9
        assert len(rec["values"]) == rec["intervals"] + 1
    again = load_model(path)
    u = in_range_voltages(model, 50_000, seed=5)
    np.testing.assert_array_equal(again.decouple(u), model.decouple(u))
    one, again_one = model.decoupler(), again.decoupler()
    assert [one(*r) for r in u[:100].tolist()] == [again_one(*r) for r in u[:100].tolist()]


def test_edited_surrogate_fails_the_integrity_check(model, tmp_path):
    doc = model_to_dict(model)
    doc["chi"]["zy"]["surrogate"]["values"][3] += 1e-6
    path = tmp_path / "edited.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(ModelFileError, match="integrity check failed"):
        load_model(path)


@pytest.mark.parametrize("recorded", [1e-6, 1e-9, 2 * MAX_SURROGATE_ERROR])
def test_surrogate_with_a_poor_bound_is_not_used(model, recorded):
    """Two chi add up per output, so even a recorded 1e-9 V per chi could break the promise."""
    doc = model_to_dict(model)
    doc["chi"]["yz"]["surrogate"]["max_error"] = recorded
    from fsdecouple.core.modelfile import content_digest

    doc["integrity"]["digest"] = content_digest(doc)
    m = model_from_dict(doc)
    assert m.fast_decoupler() is None


@pytest.mark.slow  # over ~0.6 s: the not-slow run stays under a minute
def test_table_path_keeps_the_promise_everywhere_inside_the_tables(model):
    """The promise re-derived: forces by the tables against the exact kernel sum on
    dense random points over the whole of every table (margins included).  Output a
    adds N - 1 chi, each recorded within max_error <= MAX_SURROGATE_ERROR = PROMISE / 4
    on its check grid, so |df_a| * |k_a| <= (N - 1) * PROMISE / 4 = PROMISE / 2 at
    check points; the other half is room for errors between them."""
    n_axes = len(model.k)
    grid = {}
    for c in model.chi.values():
        assert usable(c.surrogate), c.name
        grid[c.input_axis] = c.surrogate  # the chi fed by one input share a grid
    rng = np.random.default_rng(12)
    u = np.column_stack([rng.uniform(grid[b].lo, grid[b].hi, 400_000) for b in range(n_axes)])
    u = u[np.all([grid[b].covers(u[:, b]) for b in range(n_axes)], axis=0)]
    err = np.abs(model.decouple(u) - model.decouple(u, exact=True)) * np.abs(model.k)
    for a in range(n_axes):
        recorded = sum(c.surrogate.max_error for c in model.chi.values() if c.output_axis == a)
        assert recorded <= (n_axes - 1) * MAX_SURROGATE_ERROR <= PROMISE / 2
        assert err[:, a].max() <= PROMISE, a


# --- apply: formats and paths -------------------------------------------------------


def _forces(path):
    if str(path).endswith(".parquet"):
        return pq.read_table(path).to_pandas()
    return pd.read_csv(path, dtype={"t": str})


def test_apply_csv_and_parquet_give_the_same_forces(model, sim_dir, tmp_path):
    log = sim_dir / "task_voltages.csv"
    plog = tmp_path / "log.parquet"
    pq.write_table(pa.Table.from_pandas(pd.read_csv(log), preserve_index=False), plog)
    outs = {}
    for src in (log, plog):
        for suffix in (".csv", ".parquet"):
            out = tmp_path / f"{src.stem}-{src.suffix[1:]}{suffix}"
            apply_file(model, src, out, tare=200)
            outs[(src.suffix, suffix)] = _forces(out)
    ref = outs[(".csv", ".parquet")][["fx", "fy", "fz"]].to_numpy()  # the doubles
    step = 10.0 ** -force_decimals(model.settings.full_scale)
    assert step / 2 * np.abs(model.k).max() <= 1e-10  # CSV rounding: a tenth of the 1e-9 V
    for key, df in outs.items():
        assert list(df.columns) == ["t", "ux", "uy", "uz", "fx", "fy", "fz", "status"], key
        assert set(df["status"]) <= {"ok", "extrapolated"}, key
        got = df[["fx", "fy", "fz"]].to_numpy()
        if key[1] == ".csv":
            np.testing.assert_allclose(got, ref, rtol=0, atol=step / 2 * (1 + 1e-6), err_msg=str(key))
        else:
            np.testing.assert_array_equal(got, ref, err_msg=str(key))
    # round-trip text: the CSV forces are the very same doubles
    exact_text = tmp_path / "rt.csv"
    apply_file(model, log, exact_text, tare=200, round_trip=True)
    np.testing.assert_array_equal(_forces(exact_text)[["fx", "fy", "fz"]].to_numpy(), ref)
    # CSV -> Parquet: the columns the model reads as the numbers read, the others their text
    text = pd.read_csv(log, dtype=str)
    got = outs[(".csv", ".parquet")]
    pd.testing.assert_frame_equal(got[["t"]], text[["t"]])
    np.testing.assert_array_equal(got[["ux", "uy", "uz"]].to_numpy(),
                                  pd.read_csv(log)[["ux", "uy", "uz"]].to_numpy())


def test_apply_fast_path_equals_exact_path(model, sim_dir, tmp_path):
    log = sim_dir / "task_voltages.csv"
    out = tmp_path / "f.csv"
    summary = apply_file(model, log, out, tare=200)
    u = pd.read_csv(log)[["ux", "uy", "uz"]].to_numpy() - summary.offsets
    got = pd.read_csv(out)[["fx", "fy", "fz"]].to_numpy()
    np.testing.assert_array_less(np.abs(got - model.decouple(u, exact=True)) * np.abs(model.k), BOUND_V)


def test_apply_crlf_blank_lines_and_missing(model, tmp_path):
    # blank lines are rows (issue 5's contract): kept, padded to the header, 'missing'
    rows = ["t,ux,uy,uz", "0,0.1,0.0,-0.1", "", "1,,0.0,-0.1", "2, 0.2 ,0.1,-0.2", "3,0.3,0.1,-0.3"]
    lf, crlf = tmp_path / "lf.csv", tmp_path / "crlf.csv"
    lf.write_bytes("\n".join(rows).encode() + b"\n")
    crlf.write_bytes("\r\n".join(rows).encode() + b"\r\n")
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    sa = apply_file(model, lf, a)
    sb = apply_file(model, crlf, b, chunk_rows=2)
    assert a.read_bytes() == b.read_bytes()
    assert sa.rows == 5 and sa.missing_rows == 2 and sa.first_missing == sb.first_missing == [3, 4]
    lines = a.read_text().splitlines()
    assert lines[0] == "t,ux,uy,uz,fx,fy,fz,status" and lines[4].startswith("2, 0.2 ,0.1,-0.2,")
    assert lines[2] == ",,,,,,,missing" and lines[3] == "1,,0.0,-0.1,,,,missing"
    # no final line end: the last row is kept without forces, 'truncated'
    cut = tmp_path / "cut.csv"
    cut.write_bytes("\n".join(rows).encode())
    sc = apply_file(model, cut, tmp_path / "c.csv", chunk_rows=2)
    assert sc.rows == 5 and sc.truncated_rows == 1
    assert (tmp_path / "c.csv").read_text().splitlines()[-1] == "3,0.3,0.1,-0.3,,,,truncated"
    u = np.array([[0.1, 0.0, -0.1], [0.2, 0.1, -0.2], [0.3, 0.1, -0.3]])
    got = pd.read_csv(a)[["fx", "fy", "fz"]].dropna().to_numpy()
    decimals = force_decimals(model.settings.full_scale)
    np.testing.assert_array_equal(got, np.round(model.decouple(u), decimals))


HEAVY = ("fsdecouple.fitting", "libsvm", "pandas", "scipy", "matplotlib", "numba", "sklearn")


@pytest.mark.parametrize("load", ["import fsdecouple\nload = fsdecouple.load_model",
                                  "from fsdecouple.core.modelfile import load_model as load"])
def test_a_control_loop_loads_numpy_only(model, tmp_path, load):
    """Loading a model and decoupling (an array, a small call and the one-vector function)
    in a fresh interpreter loads none of the fitting stack, nor numba (large calls only)."""
    import subprocess
    import sys

    path = tmp_path / "m.json"
    save_model(model, path)
    code = (
        f"import sys\n{load}\n"
        f"m = load({str(path)!r})\n"
        "r = m.calibrated_range\n"
        "f = m.decoupler()(0.1, 0.0, -0.1), m.decouple([[0.1, 0.0, -0.1]])\n"
        "f = m.decouple([[0.1, 0.0, -0.1]] * 5000), m.decouple([[0.1, 0.0, 7.0]] * 50, exact=True)\n"
        f"print(sorted(n for n in sys.modules if n.split('.')[0] in {HEAVY!r} or any("
        f"n.startswith(h + '.') or n == h for h in {HEAVY!r})))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_fit_warns_when_a_surrogate_misses_its_bound(calib, settings, monkeypatch):
    import importlib

    model_module = importlib.import_module("fsdecouple.fitting.fit")  # the module, not fsdecouple.fit()

    real = model_module.build_pair

    def poor(chis, lo, hi, *tolerance):
        return [replace(s, max_error=1e-8) if c.name == "zx" else s
                for c, s in zip(chis, real(chis, lo, hi, *tolerance), strict=True)]

    monkeypatch.setattr(model_module, "build_pair", poor)
    # Table 2's libsvm tolerance: the warning is the point, not the solver's digits
    m = fit(calib, replace(settings, svr=replace(settings.svr, tolerance=1e-3)))
    assert any("chi_zx" in w and "exact kernel sum" in w for w in m.warnings)
    assert m.fast_decoupler() is None


@pytest.mark.slow  # over ~0.8 s: the not-slow run stays under a minute
def test_the_kernel_compiles_where_no_cache_can_be_written(model, monkeypatch):
    """A read-only install without a user cache directory: numba refuses ``cache=True``
    when the module is imported; the kernel is then compiled per process, same forces."""
    import importlib

    import numba

    r = model.calibrated_range
    u = np.random.default_rng(5).uniform(r[:, 0], r[:, 1], (500, 3))
    before = model.fast_decoupler().decouple(u, refine=2)
    real = numba.njit

    def no_locator(*args, cache=False, **kw):
        if cache:
            raise RuntimeError("cannot cache function 'eq11_rows': no locator available for file")
        return real(*args, **kw)

    kernel = importlib.import_module("fsdecouple.core.table_kernel")
    monkeypatch.setattr(numba, "njit", no_locator)
    try:
        fresh = importlib.reload(kernel)
        assert fresh.eq11_rows._cache.__class__.__name__ == "NullCache"
        np.testing.assert_array_equal(model.fast_decoupler().decouple(u, refine=2), before)
    finally:
        monkeypatch.undo()
        importlib.reload(kernel)


@pytest.mark.parametrize("k", [-1, 1.5])
def test_the_table_decoupler_refuses_a_negative_or_fractional_k(model, k):
    """The compiled loop would return zeros for K < 0: refused at the door instead."""
    with pytest.raises(ValueError, match="whole number >= 0"):
        model.fast_decoupler().decouple(np.zeros((100, 3)), refine=k)


def test_the_kernel_caches_in_the_user_cache_directory_never_in_the_package(tmp_path, monkeypatch):
    """numba's cache goes to NUMBA_CACHE_DIR when set, else the user's cache directory;
    a place that cannot be written means compiling per process, not the package folder."""
    import importlib

    import fsdecouple

    kernel = importlib.import_module("fsdecouple.core.table_kernel")
    package = Path(fsdecouple.__file__).resolve().parent
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    try:
        fresh = importlib.reload(kernel)
        where = Path(fresh.eq11_rows._cache._cache_path).resolve()
        assert where.is_relative_to(tmp_path) and not where.is_relative_to(package)
        (tmp_path / "file").write_text("")
        monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "file" / "numba"))  # cannot be made
        assert importlib.reload(kernel).eq11_rows._cache.__class__.__name__ == "NullCache"
        monkeypatch.delenv("NUMBA_CACHE_DIR")
        monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
        where = Path(importlib.reload(kernel).eq11_rows._cache._cache_path).resolve()
        assert where.is_relative_to(tmp_path / "xdg")
    finally:
        monkeypatch.undo()
        importlib.reload(kernel)


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_apply_loads_no_pandas_and_writes_pandas_own_metadata(model, tmp_path):
    """pyarrow imports pandas (0.8 s) for pa.array, pa.scalar and to_numpy; apply avoids all
    three (logs/arrow.py) and writes the Parquet output's pandas metadata itself: byte for
    byte what pandas and pyarrow write for the same columns (read back here through pandas)."""
    import subprocess
    import sys

    path = tmp_path / "m.json"
    save_model(model, path)
    log = tmp_path / "log.csv"
    log.write_text("t,ux,uy,uz,note\n0,0.1,0,-0.1,a\n1,,0.2,0.1,b\n")
    code = (
        "import sys\nfrom fsdecouple.logs.apply import apply_file\n"
        "from fsdecouple.core.modelfile import load_model\n"
        f"m = load_model({str(path)!r})\n"
        f"apply_file(m, {str(log)!r}, {str(tmp_path / 'f.csv')!r})\n"
        f"apply_file(m, {str(log)!r}, {str(tmp_path / 'f.parquet')!r})\n"
        "print('pandas' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
    table = pq.read_table(tmp_path / "f.parquet")
    plain = table.schema.remove_metadata().empty_table().to_pandas()
    assert table.schema.metadata[b"pandas"] == pa.Schema.from_pandas(
        plain, preserve_index=False).metadata[b"pandas"]
    assert pd.read_csv(tmp_path / "f.csv")["status"].tolist() == ["ok", "missing"]
