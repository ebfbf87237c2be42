"""`fsdecouple export` of a linear model (issue 25, item 7): the calibration matrix as a C
header with the svr header's API, status bits and self-test.

The reference is the model itself (``model.decouple`` of a ``linear`` model is
``u @ C.T``) and ``apply_file`` for the statuses, as for svr headers.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from conftest import SAMPLE, invoke
from test_export import (
    INPUT_NOT_FINITE,
    OUTSIDE_TABLE,
    SATURATED,
    apply_statuses,
    as_apply,
    assert_close,
    build,
    decouple,
    needs_cc,
    vectors,
)

from fsdecouple import load_config
from fsdecouple.data.calibration import load_calibration
from fsdecouple.evaluation.calibrate import fit as calibrate
from fsdecouple.export.header import emulate_float, export_header, plan_export


@pytest.fixture(scope="module")
def linear_model():
    """fit --method linear on the sample data, as the command fits it (no verdict)."""
    settings = load_config()
    model = calibrate(load_calibration(SAMPLE / "calibration", settings), settings,
                      method="linear", verdict=False)
    assert model.method == "linear" and model.matrix is not None
    return model


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_the_plan_holds_the_matrix_and_no_chi(linear_model, tmp_path):
    plan = plan_export(linear_model)
    assert plan.method == "linear" and plan.chis == [] and plan.refine == 0
    assert np.array_equal(plan.matrix, linear_model.matrix)
    # the self-test's forces are the matrix's, re-derived here
    u = plan.selftest_u[np.isfinite(plan.selftest_u).all(axis=1)]
    f = plan.selftest_f[np.isfinite(plan.selftest_u).all(axis=1)]
    assert f == pytest.approx(u @ np.asarray(linear_model.matrix).T, rel=1e-12, abs=1e-12)
    result = export_header(linear_model, tmp_path / "d.h")
    assert result.method == "linear" and result.table_bytes == 0 and result.kernel_bytes == 0
    text = (tmp_path / "d.h").read_text()
    assert '#define FSD_METHOD "linear"' in text and "#define FSD_N_CHI 0" in text
    assert "fsd_chi_axes" not in text  # C has no empty arrays


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_float_emulation_is_the_matrix_in_float(linear_model):
    plan = plan_export(linear_model, precision="float")
    rng = np.random.default_rng(3)
    lo, hi = np.asarray(linear_model.calibrated_range).T
    u32 = (lo + (hi - lo) * rng.random((1000, 3))).astype(np.float32)
    f = emulate_float(plan, u32).astype(float)
    exact = u32.astype(float) @ np.asarray(linear_model.matrix).T
    err = np.abs(f - exact) / np.asarray(linear_model.settings.full_scale)
    assert 0 < plan.float_max_error < 1e-5 and err.max() <= plan.float_max_error


@needs_cc
@pytest.mark.slow  # compiles two headers and runs 1e5 vectors through each
@pytest.mark.parametrize("precision", ["double", "float"])
def test_linear_header_matches_model_and_apply(linear_model, precision, tmp_path):
    run, text = build(linear_model, tmp_path, precision=precision)  # exits 3 if selftest fails
    u = vectors(linear_model, np.random.default_rng(1))
    if precision == "float":
        u[np.abs(u) > 1e30] = 1e30
        u = u.astype(np.float32).astype(float)
    f_c, status = run(u)
    if precision == "double":
        assert_close(f_c, decouple(linear_model, u), linear_model.settings.full_scale)
    else:
        bound = float(re.search(r"#define FSD_FLOAT_MAX_ERROR (\S+)", text).group(1))
        lo, hi = np.asarray(linear_model.calibrated_range).T
        inside = ((u >= lo) & (u <= hi)).all(axis=1)
        err = np.abs(f_c[inside] - decouple(linear_model, u[inside]))
        assert (err / np.asarray(linear_model.settings.full_scale)).max() <= bound
    assert (as_apply(status, u, 3) == apply_statuses(linear_model, u, tmp_path)).all()
    assert np.array_equal((status & INPUT_NOT_FINITE) != 0, ~np.isfinite(u).all(axis=1))
    assert (status & OUTSIDE_TABLE == 0).all() and (status & SATURATED == 0).all()


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_cli_exports_a_linear_model(tmp_path):
    model = tmp_path / "model.json"
    invoke(["fit", SAMPLE / "calibration", "--method", "linear", "--no-verdict", "-o", model])
    out = tmp_path / "decoupler.h"
    r = invoke(["export", model, "-o", out, "--json"])
    doc = json.loads(r.stdout)
    assert doc["method"] == "linear" and doc["intervals"] == {}
    digest = json.loads(model.read_text())["integrity"]["digest"]
    assert f'#define FSD_MODEL_DIGEST "{digest}"' in out.read_text()
    r = invoke(["export", model, "-o", out, "--force"])
    assert "calibration matrix" in r.stdout


@needs_cc
@pytest.mark.parametrize("precision", ["double", "float"])
def test_selftest_catches_a_damaged_matrix(linear_model, precision, tmp_path):
    """One coefficient of C a little off (1e-6 relative in double, 1e-4 in float, above
    the tolerances ~1e-9 and FSD_FLOAT_MAX_ERROR of full scale): fsd_selftest() says so."""
    import subprocess

    from test_export import CC, FLAGS

    header = tmp_path / "d.h"
    export_header(linear_model, header, precision=precision)
    text = header.read_text()
    line = re.search(r"g\[0\] = ([0-9.e+-]+)(f?) \* u\[0\]", text)
    value = float(line.group(1))
    rel = 1e-6 if precision == "double" else 1e-4
    damaged = text.replace(line.group(0), line.group(0).replace(
        line.group(1) + line.group(2), repr(value * (1 + rel)) + line.group(2), 1), 1)
    assert damaged != text
    src = tmp_path / "st.c"
    src.write_text('#define FSD_IMPLEMENTATION\n#include "d.h"\nint main(void) { return fsd_selftest(); }\n')
    for what, body in {"intact": text, "damaged": damaged}.items():
        header.write_text(body)
        subprocess.run([CC, *FLAGS, "-O2", str(src), "-o", str(tmp_path / "st"), "-lm"], check=True)
        assert (subprocess.run([str(tmp_path / "st")]).returncode == 0) == (what == "intact"), what
