"""A ``zero: intercept`` model (issue 32 item 1) decouples raw outputs: its fitted offsets
are the plan's default zero (core/plan.py), subtracted by the C header (until the
controller's ``set_zero``), the one-vector ``model.decoupler()`` and ``model.decouple(u,
zero="fitted")``; each checked against the independent eq. (11) of the model file."""

from __future__ import annotations

import csv
import json
import re
import subprocess

import numpy as np
import pytest
from conftest import eq11_from_file, invoke
from test_export import CC, FLAGS, HARNESS, build, needs_cc

from fsdecouple.core.modelfile import load_model
from fsdecouple.data.init_config import init_config
from fsdecouple.sim.poses import pose_loads
from fsdecouple.sim.rig import gauge_mix

LOADS = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")
FS = np.array([10.0, 10.0, 10.0, 0.4, 0.4, 0.4])
GAIN = 300.0  # counts per full-scale load


@pytest.fixture(scope="module")
def intercept(tmp_path_factory):
    """A fitted ``zero: intercept`` model of an 8-gauge sensor (a pose set, no unloaded
    row), its file, and the simulator's offsets."""
    tmp = tmp_path_factory.mktemp("intercept")
    offsets = np.random.default_rng(4).uniform(300, 700, 8)
    f = pose_loads(0)
    u = offsets + GAIN * (f / FS) @ gauge_mix(0, 8).T + np.random.default_rng(0).normal(0, 0.3, (len(f), 8))
    path = tmp / "poses.csv"
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([*(f"s{j}" for j in range(8)), *LOADS])
        w.writerows([[*(repr(float(v)) for v in ui), *(repr(float(v)) for v in fi)]
                     for ui, fi in zip(u, f, strict=True)])
    init_config(path, tmp / "cfg.yaml")
    invoke(["fit", path, "-c", tmp / "cfg.yaml", "-o", tmp / "m.json", "--no-verdict"])
    model = load_model(tmp / "m.json")
    assert model.zero is not None
    return model, json.loads((tmp / "m.json").read_text()), offsets


def raw_outputs(offsets, rng, rows=400):
    """Raw outputs of loads within 0.8 of full scale: the offsets plus the responses."""
    f = rng.uniform(-0.8, 0.8, (rows, 6)) * FS
    return offsets + GAIN * (f / FS) @ gauge_mix(0, 8).T


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_the_fitted_offsets_matter(intercept):
    # the reference's zero is no rounding: leaving it out moves the forces by far more
    # than any tolerance below (the offsets are ~500 counts, full scale ~300)
    model, doc, offsets = intercept
    u = raw_outputs(offsets, np.random.default_rng(1))
    gap = np.abs(eq11_from_file(doc, u, raw=True) - eq11_from_file(doc, u)) / FS
    assert gap.max() > 0.5


def test_decouple_and_decoupler_subtract_the_fitted_offsets(intercept):
    model, doc, offsets = intercept
    u = raw_outputs(offsets, np.random.default_rng(2))
    want = eq11_from_file(doc, u, raw=True)
    # the exact path: the same arithmetic as the reference, to rounding (1e-9 F.S.)
    exact = model.decouple(u, zero="fitted", exact=True)
    assert (np.abs(exact - want) / FS).max() <= 1e-9
    # zero-corrected outputs, as before, give the same forces
    again = model.decouple(u - model.zero, exact=True)
    assert (np.abs(again - want) / FS).max() <= 1e-9
    # an explicit zero replaces the fitted offsets (apply --zero)
    other = model.zero + 5.0
    np.testing.assert_allclose(model.decouple(u, zero=other, exact=True),
                               eq11_from_file(doc, u - 5.0, raw=True), rtol=0, atol=1e-9 * FS.max())
    # the one-vector function and the table path: the same plan and tables (1e-12 N)
    tables = model.decouple(u, zero="fitted")
    one = model.decoupler()
    f1 = np.array([one(*row) for row in u.tolist()])
    np.testing.assert_allclose(f1, tables, rtol=0, atol=1e-12 * FS.max())
    # the tables against the reference: each force within its chi tables' recorded errors
    # [output unit] over |k_a| (eq. 11 at K = 0), twice for margin, plus rounding
    assert model.settings.refine == 0
    chis = [*model.chi.values(), *model.own.values()]
    bound = np.array([sum(c.surrogate.max_error for c in chis
                          if c.output_axis == a and c.surrogate is not None)
                      for a in range(6)]) / np.abs(model.k)
    assert (np.abs(tables - want) <= 2 * bound + 1e-9 * FS).all()


@needs_cc
@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_float_header_subtracts_the_fitted_offsets(intercept, tmp_path):
    model, doc, offsets = intercept
    run, text = build(model, tmp_path, precision="float")
    u = raw_outputs(offsets, np.random.default_rng(6)).astype(np.float32)
    want = eq11_from_file(doc, u.astype(float), raw=True)
    f_c, _ = run(u)
    # its own promise, as the header states it (exporting again to read it costs the
    # float bound's 140,000 points once more)
    bound = float(re.search(r"#define FSD_FLOAT_MAX_ERROR (\S+)", text).group(1))
    assert (np.abs(f_c - want) / FS).max() <= bound


@needs_cc
@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_c_header_subtracts_the_fitted_offsets_until_set_zero(intercept, tmp_path):
    model, doc, offsets = intercept
    run, text = build(model, tmp_path)
    assert "Zero: u are raw outputs" in text
    u = raw_outputs(offsets, np.random.default_rng(3))
    want = eq11_from_file(doc, u, raw=True)
    f_c, _ = run(u)
    # the header's tables, as it states them, then rounding
    tol = float(re.search(r"#define FSD_TABLE_MAX_ERROR (\S+)", text).group(1)) + 1e-9
    assert (np.abs(f_c - want) / FS).max() <= tol
    # set_zero(u0) replaces the fitted offsets by the controller's zero reading
    src = tmp_path / "set_zero.c"
    src.write_text(HARNESS.replace("    while (fread", "    {{ double z[FSD_N_OUTPUTS]; int j;\n"
                                   "      for (j = 0; j < FSD_N_OUTPUTS; ++j) z[j] = 5.0 + j;\n"
                                   "      fsd_set_zero(z); }}\n    while (fread")
                   .format(P="FSD_", p="fsd_", header="decoupler.h", real="double", fn="fsd_decouple"))
    exe = tmp_path / "set_zero"
    subprocess.run([CC, *FLAGS, str(src), "-o", str(exe), "-lm"], check=True, cwd=tmp_path)
    (tmp_path / "in.bin").write_bytes(np.ascontiguousarray(u, dtype=float).tobytes())
    subprocess.run([str(exe), str(tmp_path / "in.bin"), str(tmp_path / "out.bin")], check=True)
    rec = np.dtype([("f", "<f8", 6), ("s", "<u4")])
    f_z = np.fromfile(tmp_path / "out.bin", dtype=rec)["f"]
    z = 5.0 + np.arange(8)
    assert (np.abs(f_z - eq11_from_file(doc, u - z + model.zero, raw=True)) / FS).max() <= tol
