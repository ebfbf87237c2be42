"""Property tests: whatever the input, a valid result or an FsdecoupleError, never NaN.

Generated CSV text goes to ingest and apply, generated arrays to decoupling and
generated calibration sets to fit.  Example counts stay modest for CI on 2 cores.
"""

from __future__ import annotations

import contextlib
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import SAMPLE
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from fsdecouple import FsdecoupleError, load_calibration, load_config
from fsdecouple.apply import STATUSES, apply_file
from fsdecouple.calibration import from_table
from fsdecouple.config import Settings
from fsdecouple.fit import fit

SETTINGS = settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
LENIENT = Settings(min_repetitions=1)


@pytest.fixture(scope="module")
def model():
    return fit(load_calibration(SAMPLE / "calibration", load_config()), load_config())


numbers = st.one_of(
    st.floats(-2.0, 2.0).map(lambda v: f"{v:.6f}"),
    st.sampled_from(["0", "0.000", "-0.0", "1e3", "-1e-300", "1e308"]),
)
junk = st.sampled_from(["", " ", "nan", "NaN", "inf", "-inf", "n/a", "abc", "1,5", "1;5", "0x10",
                        "1e999", "--1", "1.2.3", "\t", "∞", "０"])
cells = st.one_of(numbers, numbers, numbers, junk)
# what a data logger writes when a channel drops out: kept rows, status 'missing'
gaps = st.sampled_from(["", "nan", "NaN", " ", "NA"])
log_cells = st.one_of(*[numbers] * 8, gaps)
headers = st.lists(
    st.sampled_from(["t", "ux", "uy", "uz", "fx", "axis", "status", "", "u x", "ux;uy", "uy"]),
    min_size=0, max_size=6,
)


@st.composite
def csv_texts(draw, header=None, cells=cells, ragged=True):
    names = draw(headers) if header is None else header
    n_rows = draw(st.integers(0, 12))
    width = (st.integers(max(0, len(names) - 1), len(names) + 1) if ragged
             else st.just(len(names)))
    rows = [",".join(draw(st.lists(cells, min_size=w, max_size=w)))
            for w in (draw(width) for _ in range(n_rows))]
    text = "\n".join([",".join(names), *rows])
    ending = draw(st.sampled_from(["\n", "", "\n\n"]))
    bom = draw(st.sampled_from(["", "\ufeff"]))
    eol = draw(st.sampled_from(["\n", "\r\n"]))
    return (bom + text + ending).replace("\n", eol)


@contextlib.contextmanager
def written(text: str):
    """The text in a fresh directory (hypothesis reruns the body; no tmp_path per example)."""
    d = Path(tempfile.mkdtemp(prefix="fsd-prop-"))
    try:
        p = d / "data.csv"
        p.write_text(text, encoding="utf-8", newline="")
        yield p
    finally:
        shutil.rmtree(d)


@SETTINGS
@given(csv_texts(header=["t", "ux", "uy", "uz"], cells=log_cells, ragged=False)
       | csv_texts(header=["ux", "uy", "uz"], cells=log_cells) | csv_texts(header=["t", "ux", "uy", "uz"])
       | csv_texts(header=None))
def test_voltage_log_contract(model, text):
    """apply: every data row comes out, in order, with a known status; or a clean refusal."""
    with written(text) as log:
        out = log.parent / "forces.csv"
        try:
            summary = apply_file(model, log, out)
        except FsdecoupleError:
            event("refused")
            assert not out.exists() and [p.name for p in log.parent.iterdir()] == ["data.csv"]
            return
        event("decoupled")
        f = pd.read_csv(out, dtype=str, keep_default_na=False, na_filter=False)
    assert len(f) == summary.rows and set(f["status"]) <= set(STATUSES)
    forces = f[["fx", "fy", "fz"]]
    has = f["status"].isin(["ok", "extrapolated"]).to_numpy()
    assert np.isfinite(forces[has].astype(float).to_numpy()).all()
    assert (forces[~has] == "").all().all()


@st.composite
def calibration_tables(draw):
    """Structurally plausible sets: sweeps with a zero row, random sensors, slips."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    k = draw(st.lists(st.sampled_from([0.0, 1e-9, 0.013, 0.008, -0.01, 5.0]), min_size=3,
                      max_size=3))
    coupling = draw(st.sampled_from([0.0, 0.01, 0.3]))
    noise = draw(st.sampled_from([0.0, 1e-4, 0.05]))
    n_reps = draw(st.integers(1, 2))
    n_points = draw(st.integers(1, 6))
    rows = []
    for rep in range(1, n_reps + 1):
        for a, axis in enumerate("xyz"):
            loads = np.concatenate([[0.0], draw(st.lists(
                st.sampled_from([-100.0, -50.0, -10.0, 10.0, 50.0, 100.0, 0.0]),
                min_size=n_points, max_size=n_points))])
            for load in loads:
                f = np.zeros(3)
                f[a] = load
                u = f * np.asarray(k) + coupling * np.sin(load / 30.0) * (np.arange(3) != a)
                u = u + rng.normal(0, noise, 3) + 0.01 * rep
                rows.append((rep, axis, "f", len(rows) + 2, *f, *u))
    if draw(st.booleans()):
        rows = rows + rows[: draw(st.integers(0, len(rows)))]  # duplicates
    return pd.DataFrame(rows, columns=["repetition", "axis", "file", "row", "fx", "fy", "fz",
                                       "ux", "uy", "uz"])


@settings(max_examples=40, deadline=None)
@given(calibration_tables())
def test_fit_contract(table):
    """fit: a finite model whose decoupling is never NaN, or an FsdecoupleError."""
    try:
        cs = from_table(table, LENIENT, files=(("f", ""),))
        m = fit(cs, LENIENT, workers=1)
    except FsdecoupleError:
        event("refused")
        return
    event("fitted")
    assert np.isfinite(m.k).all() and (m.k != 0).all()
    assert all(np.isfinite(c.dual_coef).all() and np.isfinite(c.rho) for c in m.chi.values())
    assert not np.isnan(m.decouple(cs.voltages)).any()


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(*[st.floats(allow_nan=False, allow_infinity=False)] * 3),
                min_size=0, max_size=20))
def test_decouple_never_nan(model, rows):
    u = np.asarray(rows, dtype=float).reshape(-1, 3)
    with np.errstate(over="ignore"):
        f = model.decouple(u)
    assert f.shape == u.shape and not np.isnan(f).any()
    small = (np.abs(u) < 1e6).all(axis=1)
    assert np.isfinite(f[small]).all()


@st.composite
def calibration_texts(draw):
    """A plausible single-CSV calibration set, then a few cells spoilt."""
    table = draw(calibration_tables())
    cols = ["repetition", "axis", "fx", "fy", "fz", "ux", "uy", "uz"]
    if draw(st.booleans()):
        cols.remove("axis")
    lines = [",".join(cols)] + [
        ",".join(str(r[c]) if c in ("repetition", "axis") else f"{r[c]:.7g}" for c in cols)
        for r in table.to_dict("records")
    ]
    for _ in range(draw(st.integers(0, 2))):
        i = draw(st.integers(1, len(lines) - 1))
        fields = lines[i].split(",")
        fields[draw(st.integers(0, len(fields) - 1))] = draw(junk)
        lines[i] = ",".join(fields)
    return "\n".join(lines) + draw(st.sampled_from(["\n", ""]))


@SETTINGS
@given(calibration_texts() | csv_texts() | csv_texts(
    header=["repetition", "axis", "fx", "fy", "fz", "ux", "uy", "uz"]))
def test_calibration_ingest_contract(text):
    try:
        with written(text) as path:
            cs = load_calibration(path, LENIENT)
    except FsdecoupleError:
        event("refused")
        return
    event("read")
    assert np.isfinite(cs.voltages).all() and np.isfinite(cs.forces).all()
