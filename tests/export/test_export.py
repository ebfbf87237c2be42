"""`fsdecouple export`: the generated C header, compiled and run against the Python model.

Each header is compiled with ``cc -std=c99 -Wall -Wextra -Werror -pedantic`` and
linked into a small harness that reads voltage vectors from a binary file and
writes forces and status words back.  The references are ``model.decouple``
(forces) and ``apply_file`` (statuses), so nothing here restates the C.
"""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
import subprocess

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import ROOT, SAMPLE, invoke

from fsdecouple import fit, load_config, load_model
from fsdecouple.core.model import CouplingErrorModel
from fsdecouple.core.modelfile import model_to_dict
from fsdecouple.core.surrogate import hermite
from fsdecouple.errors import ConfigError, FsdecoupleError
from fsdecouple.export.header import emulate_float, export_header, plan_export
from fsdecouple.export.resample import resample
from fsdecouple.logs.apply import apply_file
from fsdecouple.units import Units

pytestmark = pytest.mark.slow  # compiles C headers and runs 1e5 vectors through them

CC = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
needs_cc = pytest.mark.skipif(CC is None, reason="no C compiler (cc, gcc or clang) on PATH")
FLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]
GOLDEN = ROOT / "tests" / "fixtures" / "golden"
INPUT_NOT_FINITE, NOT_FINITE, OUTSIDE_TABLE, SATURATED = 1 << 17, 1 << 18, 1 << 16, 1 << 19
# The double header's promise, as the fast path's: |df_a| <= 1e-9 FS_a, i.e. 1e-9 of
# the full-scale output |k_a| FS_a [V] in voltage terms.  Far outside the range the
# forces themselves grow, and (u - e) * (1/k) and u/k + ... round differently by
# ~1e-16 |f|: 1e-12 |f| covers that without hiding anything the first term catches.
REL_FS, REL_F = 1e-9, 1e-12

HARNESS = r"""
#define {P}IMPLEMENTATION
#include "{header}"
#include <stdio.h>
int main(int argc, char **argv)
{{
    {real} u[{P}N_OUTPUTS], f[{P}N_COMPONENTS];
    uint32_t s;
    FILE *in, *out;
    if (argc != 3 || {p}selftest() != 0) return 3;
    in = fopen(argv[1], "rb");
    out = fopen(argv[2], "wb");
    if (!in || !out) return 4;
    while (fread(u, sizeof u, 1, in) == 1) {{
        s = {fn}(u, f);
        fwrite(f, sizeof f, 1, out);
        fwrite(&s, sizeof s, 1, out);
    }}
    fclose(in);
    return fclose(out) != 0;
}}
"""


@pytest.fixture(scope="module")
def sample_model(sample_model):
    """The model of the committed sample data (it has surrogate tables): the session's
    `fsdecouple fit` of it (conftest's sample_model), loaded."""
    return load_model(sample_model)


@pytest.fixture(scope="module")
def kernel_model():
    """The sample data fitted with extrapolation: kernel (the kernel sum beyond the range),
    at Table 2's libsvm tolerance: the header is checked against this model, whatever its
    solver's last digits (~1.2 s of CPU -> ~0.3 s)."""
    return fit(SAMPLE / "calibration", load_config(extrapolation="kernel", tolerance=1e-3),
               verdict=False)


@pytest.fixture(scope="module")
def rotated_model(tmp_path_factory):
    """The sample data fitted with a config that rotates into a reference frame."""
    a, b = np.radians(30.0), np.radians(10.0)
    rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    r = rz @ rx
    cfg = tmp_path_factory.mktemp("cfg") / "rot.yaml"
    cfg.write_text("rotation:\n" + "".join(f"  - [{', '.join(map(repr, row))}]\n" for row in r.tolist()))
    # Table 2's libsvm tolerance: the header is checked against this model, whatever its
    # solver's last digits
    settings = load_config(cfg, tolerance=1e-3)
    assert settings.rotation is not None and settings.svr.tolerance == 1e-3
    return fit(SAMPLE / "calibration", settings, verdict=False)  # the header needs no verdict


class _Settings:
    """Settings with attributes a later model may have (refine, units, limits)."""

    def __init__(self, base, **extra):
        self._base, self._extra = base, extra

    def __getattr__(self, name):
        return self._extra[name] if name in self._extra else getattr(self._base, name)


def build(model, tmp_path, *, opt="-O2", name="decoupler.h", exported=None, **kw):
    """Export ``model`` (or take ``exported``, (header text, export result), of it),
    compile it into the harness; return (run, header text)."""
    header = tmp_path / name
    if exported is None:
        result = export_header(model, header, force=True, **kw)
    else:
        header.write_text(exported[0])
        result = exported[1]
    p = kw.get("prefix", "fsd_")
    real = "float" if result.precision == "float" else "double"
    fn = f"{p}decouple_f" if real == "float" else f"{p}decouple"
    src = tmp_path / f"harness_{name}.c"
    src.write_text(HARNESS.format(P=p.upper(), p=p, header=name, real=real, fn=fn))
    exe = tmp_path / f"harness_{name}{opt}"
    subprocess.run([CC, *FLAGS, opt, str(src), "-o", str(exe), "-lm"], check=True,
                   capture_output=True, text=True)
    n = result.n_components
    rec = np.dtype([("f", "<f8" if real == "double" else "<f4", n), ("s", "<u4")])

    def run(u: np.ndarray):
        (tmp_path / "in.bin").write_bytes(np.ascontiguousarray(u, dtype=rec["f"].base).tobytes())
        proc = subprocess.run([str(exe), str(tmp_path / "in.bin"), str(tmp_path / "out.bin")],
                              capture_output=True)
        assert proc.returncode == 0, f"harness exit {proc.returncode} (3: selftest failed)"
        out = np.fromfile(tmp_path / "out.bin", dtype=rec)
        return out["f"].astype(float), out["s"]

    return run, header.read_text()


def vectors(model, rng, n_random=65_000):
    """>= 1e5 test vectors: inside and around the range, the thresholds, off the tables."""
    cal = np.asarray(model.calibrated_range)
    lo, hi = cal.T
    span = hi - lo
    n = lo.size
    rows = [lo + span * rng.random((n_random, n)),  # calibrated range
            lo - 0.3 * span + 1.6 * span * rng.random((25_000, n)),  # margin and table ends
            lo - 2.0 * span + 5.0 * span * rng.random((10_000, n))]  # mostly off the tables
    edges = []
    for c in model.chi.values():
        b = c.input_axis
        m = 0.01 * span[b]  # apply's margin: the extrapolation thresholds
        pts = [lo[b] - m, hi[b] + m, lo[b], hi[b]]
        if c.surrogate is not None:
            pts += [c.surrogate.lo, c.surrogate.hi]
        for x in pts:
            for y in (np.nextafter(x, -np.inf), x, np.nextafter(x, np.inf)):
                base = lo + span * rng.random((40, n))
                base[:, b] = y
                edges.append(base)
    rows.append(np.concatenate(edges))
    special = lo + span * rng.random((300, n))
    special[:100, 0] = np.nan
    special[100:200, n - 1] = 1e307  # eq. (11) overflows: u / k > max double
    special[200:, :] = np.nan
    rows.append(special)
    u = np.concatenate(rows)
    assert len(u) >= n_random + 35_000  # >= 1e5 with the default
    return u


def apply_statuses(model, u, tmp_path):
    """What `fsdecouple apply` says of each row, given as a Parquet log (NaN as a null, a
    missing value like an empty CSV cell; the same statuses as a CSV log at a seventh
    of the CPU: no 1e5 rows of text to write and parse)."""
    log = tmp_path / "log.parquet"
    pq.write_table(pa.table({c: pa.array(u[:, i], from_pandas=True)
                             for i, c in enumerate(("ux", "uy", "uz"))}), log)
    out = tmp_path / "forces.parquet"
    apply_file(model, log, out, force=True)
    return np.array(pq.read_table(out).column("status").to_pylist())


def as_apply(status: np.ndarray, u: np.ndarray, n: int) -> np.ndarray:
    """The header's status word in apply's words (documented in the header comment)."""
    out = np.full(status.shape, "ok", dtype=object)
    out[(status & ((1 << n) - 1)) != 0] = "extrapolated"
    out[(status & NOT_FINITE) != 0] = "not_finite"
    out[np.isnan(u).any(axis=1)] = "missing"  # apply: a NaN voltage is a missing one
    return out


def decouple(model, u, **kw):
    """model.decouple, quiet about the rows that overflow on purpose (one thread:
    numpy's error state is per thread, as apply does it)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return model.decouple(u, workers=1, **kw)


def assert_close(f_c, f_py, full_scale):
    ok = np.isfinite(f_py).all(axis=1)
    assert np.array_equal(np.isfinite(f_c).all(axis=1), ok)
    err = np.abs(f_c[ok] - f_py[ok])
    limit = REL_FS * np.asarray(full_scale) + REL_F * np.abs(f_py[ok])
    worst = np.max(err / limit)
    assert worst <= 1.0, f"worst |df| is {worst:.3g} x the allowance"


@pytest.fixture(scope="module")
def references():
    """Per model: the test vectors, model.decouple's forces and apply's statuses of them
    (~1 s of CPU a model), computed by the first header test that needs them."""
    return {}


@needs_cc
@pytest.mark.parametrize("which", ["sample", "rotated", "kernel"])
@pytest.mark.parametrize("opt", ["-O0", "-O2"])
def test_double_header_matches_model_and_apply(which, opt, request, tmp_path, references):
    """sample and rotated extrapolate by tangents, kernel by the kernel sum: the
    vectors reach far beyond the calibrated range and the tables."""
    model = request.getfixturevalue(f"{which}_model")
    run, _ = build(model, tmp_path, opt=opt)
    if which not in references:  # the -O0 and -O2 headers against the same references
        u = vectors(model, np.random.default_rng(1))
        references[which] = u, decouple(model, u), apply_statuses(model, u, tmp_path)
    u, f_py, statuses = references[which]
    f_c, status = run(u)
    assert_close(f_c, f_py, model.settings.full_scale)
    assert (as_apply(status, u, 3) == statuses).all()
    # the status bits the apply statuses do not show, against the definitions
    assert np.array_equal((status & INPUT_NOT_FINITE) != 0, ~np.isfinite(u).all(axis=1))
    covered = np.ones(len(u), bool)
    with np.errstate(over="ignore"):
        for c in model.chi.values():
            covered &= c.surrogate.covers(u[:, c.input_axis])
    assert np.array_equal((status & OUTSIDE_TABLE) == 0, covered)
    assert (status & SATURATED == 0).all()


@needs_cc
@pytest.mark.parametrize("which", ["sample", "rotated"])
def test_float_header_within_its_bound(which, request, tmp_path):
    model = request.getfixturevalue(f"{which}_model")
    exported = request.getfixturevalue("sample_float_header") if which == "sample" else \
        _float_export(model, tmp_path / "export")
    run, text = build(model, tmp_path, exported=exported[:2])
    plan = exported[2]
    bound = float(re.search(r"#define FSD_FLOAT_MAX_ERROR (\S+)", text).group(1))
    assert 0 < bound < 1e-5  # float: ~1e-7 of full scale from rounding u / k alone
    rng = np.random.default_rng(2)
    lo, hi = np.asarray(model.calibrated_range).T
    u32 = (lo + (hi - lo) * rng.random((100_000, 3))).astype(np.float32)
    f_c, status = run(u32)
    u = u32.astype(float)
    err = np.abs(f_c - model.decouple(u)) / np.asarray(model.settings.full_scale)
    assert err.max() <= bound
    # the emulation the bound comes from is the C: equal but for a rare last-bit difference
    emu = emulate_float(plan, u32).astype(float)
    assert np.mean(emu == f_c) > 0.99 and np.max(np.abs(emu - f_c) / np.abs(f_c).clip(1)) < 1e-6
    # statuses on the whole vector set, float inputs: the float thresholds are exact
    w = vectors(model, rng, 20_000)
    w[np.abs(w) > 1e30] = 1e30  # the overflow rows: float overflows at ~3e38 / |1/k| already
    w = w.astype(np.float32)
    _, status = run(w)
    assert (as_apply(status, w.astype(float), 3) == apply_statuses(model, w.astype(float), tmp_path)).all()


def _float_export(model, directory):
    """``model``'s float header: (its text, the export's result, the plan it was written
    from, recorded as export_header made it: planning it again would compute its float
    bound again, ~0.6 s of CPU)."""
    import fsdecouple.export.header as header_module

    directory.mkdir(exist_ok=True)
    header = directory / "f.h"
    plans = []
    real_plan_export = header_module.plan_export
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(header_module, "plan_export",
                   lambda *a, **k: plans.append(real_plan_export(*a, **k)) or plans[-1])
        result = export_header(model, header, precision="float")
    assert len(plans) == 1 and plans[0].precision == "float" == result.precision
    return header.read_text(), result, plans[0]


@pytest.fixture(scope="module")
def sample_float_header(sample_model, tmp_path_factory):
    """The sample model's float header, exported once for the tests that compile it as it
    is or damaged (each export computes its float bound: ~0.6 s of CPU): (its text, the
    export's result, its plan)."""
    return _float_export(sample_model, tmp_path_factory.mktemp("float"))


@needs_cc
def test_float_bound_holds_with_fused_multiply_add(sample_model, sample_float_header, tmp_path):
    """The 2x safety factor of FSD_FLOAT_MAX_ERROR covers a compiler contracting the
    Horner steps into FMAs (the emulation rounds each product separately)."""
    header = tmp_path / "f.h"
    text, result, _ = sample_float_header
    header.write_text(text)
    src = tmp_path / "fma.c"
    src.write_text(HARNESS.format(P="FSD_", p="fsd_", header="f.h", real="float", fn="fsd_decouple_f"))
    flags = ["-O3", "-march=native", "-ffp-contract=fast"]
    built = subprocess.run([CC, "-std=c99", *flags, str(src), "-o", str(tmp_path / "fma"), "-lm"],
                           capture_output=True)
    if built.returncode != 0:
        pytest.skip(f"{CC} does not take {' '.join(flags)}")
    lo, hi = np.asarray(sample_model.calibrated_range).T
    u32 = (lo + (hi - lo) * np.random.default_rng(6).random((100_000, 3))).astype(np.float32)
    (tmp_path / "in.bin").write_bytes(u32.tobytes())
    subprocess.run([str(tmp_path / "fma"), str(tmp_path / "in.bin"), str(tmp_path / "out.bin")],
                   check=True)
    rec = np.dtype([("f", "<f4", 3), ("s", "<u4")])
    f = np.fromfile(tmp_path / "out.bin", dtype=rec)["f"].astype(float)
    err = np.abs(f - sample_model.decouple(u32.astype(float))) / np.asarray(sample_model.settings.full_scale)
    assert err.max() <= result.float_max_error


@needs_cc
def test_the_float_header_computes_in_float(sample_float_header, tmp_path):
    """fabs on a float promoted it to double (-Wdouble-promotion), which an MCU with a
    single-precision FPU runs in software."""
    (tmp_path / "f.h").write_text(sample_float_header[0])
    src = tmp_path / "f.c"
    src.write_text('#define FSD_IMPLEMENTATION\n#include "f.h"\nint main(void) { return 0; }\n')
    subprocess.run([CC, *FLAGS, "-Wdouble-promotion", "-c", str(src), "-o", str(tmp_path / "f.o")],
                   check=True)


@needs_cc
@pytest.mark.parametrize("precision", ["double", "float"])
def test_selftest_catches_a_damaged_header(sample_model, kernel_model, precision, tmp_path,
                                          request):
    """A slope a little off, or one support vector moved: fsd_selftest() reports it.

    1e-6 relative in double (tolerance ~1e-9 of full scale), 1e-4 in float (tolerance
    FSD_FLOAT_MAX_ERROR, ~3e-7 of full scale, below 1e-4 of the vectors' forces).
    """
    header = tmp_path / "d.h"
    if precision == "float":  # the module's export of it
        header.write_text(request.getfixturevalue("sample_float_header")[0])
    else:
        export_header(sample_model, header, precision=precision)
    text = header.read_text()
    slope = re.search(r"\) \* ([0-9.e+-]+f?);", text).group(1)  # 1 / k_00 in eq. (11)
    value = float(slope.rstrip("f"))
    rel = 1e-6 if precision == "double" else 1e-4
    damaged = {"slope": text.replace(slope, repr(value * (1 + rel)) + "f" * slope.endswith("f"), 1)}
    if precision == "double":  # the vector beyond the tables: chi's tangent beyond the range
        line = re.search(r"if \(u > \S+\) return ([0-9.e+-]+) \+.*", text)
        damaged["tangent"] = text.replace(
            line.group(0), line.group(0).replace(line.group(1), repr(float(line.group(1)) + 1e-3), 1), 1)
        # ... or, under extrapolation: kernel, a kernel sum
        export_header(kernel_model, header, force=True)
        kernel = header.read_text()
        sv = re.search(r"fsd_sv0\[\d+\] = \{\n    ([0-9.e+-]+),", kernel).group(1)
        damaged["support vector"] = kernel.replace(sv, repr(float(sv) + 1e-3), 1)
        damaged["intact kernel"] = kernel
    src = tmp_path / "st.c"
    src.write_text('#define FSD_IMPLEMENTATION\n#include "d.h"\nint main(void) { return fsd_selftest(); }\n')
    for what, body in {"intact": text, **damaged}.items():
        header.write_text(body)
        subprocess.run([CC, *FLAGS, "-O2", str(src), "-o", str(tmp_path / "st"), "-lm"], check=True)
        bad = subprocess.run([str(tmp_path / "st")]).returncode
        assert (bad == 0) == what.startswith("intact"), what


@needs_cc
def test_kernel_sums_only_without_surrogates(tmp_path):
    model = load_model(GOLDEN / "model-v1-without-surrogates.json")
    run, text = build(model, tmp_path)
    assert "#define FSD_TABLE_BYTES 0" in text
    u = vectors(model, np.random.default_rng(3), 5_000)[::5]
    f_c, status = run(u)
    assert_close(f_c, decouple(model, u), model.settings.full_scale)
    assert (status & OUTSIDE_TABLE == 0).all()  # no tables: never "outside" one
    # --max-error builds tables from the kernel sums even where the model has none
    run, text = build(model, tmp_path, name="coarse.h", max_error=1e-5)
    assert "#define FSD_TABLE_BYTES 0" not in text
    f_c, status = run(u)
    ok = np.isfinite(u).all(axis=1) & (np.abs(u) < 1e6).all(axis=1)
    err = np.abs(f_c[ok] - decouple(model, u[ok])) / np.asarray(model.settings.full_scale)
    assert err.max() <= 1e-5 and (status[ok] & OUTSIDE_TABLE == 0).any()


class _Chi:
    """A chi of the sample model re-wired to other axes (for an N-axis test model)."""

    def __init__(self, base, out: int, inp: int):
        self._base, self.output_axis, self.input_axis = base, out, inp

    def __getattr__(self, name):
        return getattr(self._base, name)

    def __call__(self, u):
        return self._base(u)


class _NAxisModel:
    """An N-axis model from the sample's chi: channel b >= 3 reuses channel b % 3's
    voltages and chi.  Its decouple() is eq. (11) written out here with kernel sums."""

    def __init__(self, model, n: int):
        src = lambda b: next(c for c in model.chi.values() if c.input_axis == b % 3)  # noqa: E731
        self.chi = {f"c{a}{b}": _Chi(src(b), a, b) for a in range(n) for b in range(n) if a != b}
        self.k = np.array([model.k[b % 3] * (1 + 0.1 * (b // 3)) for b in range(n)])
        fs = tuple(model.settings.full_scale[b % 3] for b in range(n))
        self.settings = _Settings(model.settings, full_scale=fs, rotation=None)
        self.calibrated_range = np.asarray(model.calibrated_range)[[b % 3 for b in range(n)]]
        self._doc = model_to_dict(model)
        self.method = "svr"

    extrapolation_limits = CouplingErrorModel.extrapolation_limits  # from calibrated_range

    @property
    def n_outputs(self) -> int:
        return len(self.k)

    def plan(self):
        """Eq. (11) alone, every chi a kernel sum (core/plan.py)."""
        from fsdecouple.core.plan import Couple, Plan, Term

        terms = tuple(Term(c.output_axis, c.input_axis, c) for c in self.chi.values())
        fs_out = np.abs(self.k) * np.asarray(self.settings.full_scale)
        return Plan((Couple(self.k, terms, 0, fs_out),), len(self.k), len(self.k))

    def decouple(self, u, *, rotate=True, exact=False, workers=None):
        u = np.asarray(u, dtype=float)
        f = u.copy()
        for c in self.chi.values():
            f[:, c.output_axis] -= c(u[:, c.input_axis])
        return f / self.k


@needs_cc
@pytest.mark.parametrize("n", [2, 4])
def test_any_number_of_axes(sample_model, n, tmp_path, monkeypatch):
    import fsdecouple.export.header as export_module

    model = _NAxisModel(sample_model, n)
    # the model file of a stand-in: the sample's document (digest, format_version)
    monkeypatch.setattr(export_module, "model_to_dict", lambda m: m._doc)
    run, text = build(model, tmp_path)
    assert f"#define FSD_N_COMPONENTS {n}" in text and f"#define FSD_N_CHI {n * (n - 1)}" in text
    lo, hi = model.calibrated_range.T
    u = lo - 0.1 * (hi - lo) + 1.2 * (hi - lo) * np.random.default_rng(7).random((20_000, n))
    f_c, status = run(u)
    assert_close(f_c, model.decouple(u), model.settings.full_scale)
    margin = 0.01 * (hi - lo)  # apply's RANGE_MARGIN
    outside = (u < lo - margin) | (u > hi + margin)
    bits = (status[:, None] >> np.arange(n)) & 1
    assert np.array_equal(bits == 1, outside) and outside.any(axis=0).all()


@needs_cc
def test_max_error_picks_coarse_tables_within_it(sample_model, tmp_path):
    full, _ = build(sample_model, tmp_path, name="full.h")
    e = 1e-5
    run, text = build(sample_model, tmp_path, max_error=e)
    coarse = int(re.search(r"#define FSD_TABLE_BYTES (\d+)", text).group(1))
    assert coarse < 49152 / 8  # 6 tables of 256 intervals x 4 doubles is 49152 bytes
    lo, hi = np.asarray(sample_model.calibrated_range).T
    u = lo - 0.3 * (hi - lo) + 1.6 * (hi - lo) * np.random.default_rng(4).random((100_000, 3))
    f_c, _ = run(u)
    err = np.abs(f_c - sample_model.decouple(u, exact=True)) / np.asarray(sample_model.settings.full_scale)
    assert e / 20 < err.max() <= e  # coarse: uses much of the allowance, keeps it
    plan = plan_export(sample_model, max_error=e)
    for cp in plan.chis:  # the coarsest: one interval fewer breaks the chi's share of e
        target = e * plan.full_scale[cp.out] * abs(plan.k[cp.out]) / 2
        assert resample(cp, cp.table.intervals - 1).max_error > target >= cp.table.max_error


def test_resampled_table_equals_the_models_surrogate(sample_model):
    """resample() on the model's own grid rebuilds its table; the one Hermite formula
    (surrogate.hermite) checked by its definition: each cubic meets the knot values and
    slopes at both ends of its interval."""
    plan = plan_export(sample_model)
    for cp, c in zip(plan.chis, sample_model.chi.values(), strict=True):
        s = c.surrogate
        h = (s.hi - s.lo) / s.intervals
        c0, c1, c2, c3 = hermite(s.values, s.slopes, h)
        np.testing.assert_allclose(c0, s.values[:-1], rtol=0, atol=0)
        np.testing.assert_allclose(c0 + c1 + c2 + c3, s.values[1:], rtol=0, atol=1e-12)
        np.testing.assert_allclose(c1 / h, s.slopes[:-1], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose((c1 + 2 * c2 + 3 * c3) / h, s.slopes[1:], rtol=1e-9, atol=1e-9)
        again = resample(cp, s.intervals)
        assert np.allclose(again.coefficients(), s.coefficients(), rtol=0, atol=1e-12)
        assert again.max_error == pytest.approx(s.max_error, rel=0.1, abs=1e-12)


@needs_cc
def test_refinement_steps_invert_the_coupling_model(sample_model, tmp_path):
    """With settings.refine, the fixed point on the prime voltages undoes eq. (1).

    Simulate measured voltages from known prime voltages p (u_a = p_a + sum_b
    chi_ab(p_b), the coupling error model of eq. (1) and eq. (4)); 30 steps then
    recover p, so the forces are p_a / k_aa.
    """
    model = dataclasses.replace(sample_model, settings=_Settings(sample_model.settings, refine=30))
    run, text = build(model, tmp_path)
    assert "#define FSD_REFINE_STEPS 30" in text
    lo, hi = np.asarray(model.calibrated_range).T
    p = lo + (hi - lo) * np.random.default_rng(5).random((20_000, 3))
    u = p + model.coupling_errors(p)
    f_c, _ = run(u)
    assert_close(f_c, p / model.k, model.settings.full_scale)


@needs_cc
def test_saturation_limits_compare_the_values_passed_in(sample_model, tmp_path):
    run, text = build(sample_model, tmp_path, limits={"ux": [-1.0, 1.0], 2: (-1.1, 0.05)})
    assert "u[0] <= -1.0 or u[0] >= 1.0" in text
    x = [-1.0, np.nextafter(-1.0, 0), 0.0, np.nextafter(1.0, 0), 1.0, 1.5]
    u = np.array([[v, 0.0, -0.5] for v in x] + [[0.0, 0.0, 0.05], [0.0, 0.0, -1.1]])
    _, status = run(u)
    assert ((status & SATURATED) != 0).tolist() == [True, False, False, False, True, True, True, True]
    with pytest.raises(ConfigError, match="unknown channel 'uq'"):
        export_header(sample_model, tmp_path / "x.h", limits={"uq": [0, 1]})
    with pytest.raises(ConfigError, match="expected finite lo < hi"):
        export_header(sample_model, tmp_path / "x.h", limits={"uy": [1, 0]})


@needs_cc
def test_sensor_name_and_units_are_escaped_literally(sample_model, tmp_path):
    evil = 'rig */ #define X "q" \\ ??= 100 % \u00e9\n\t end'
    # units are checked against a list (fsdecouple.units); the sensor name is free text
    settings = dataclasses.replace(sample_model.settings, sensor=evil, units=Units("kN", "mV"))
    model = dataclasses.replace(sample_model, settings=settings)
    header = tmp_path / "evil.h"
    export_header(model, header, prefix="ev_")
    src = tmp_path / "evil.c"
    src.write_text('#define EV_IMPLEMENTATION\n#include "evil.h"\n#include <stdio.h>\n'
                   'int main(void) { fputs(EV_SENSOR, stdout); fputs("|", stdout);'
                   ' fputs(EV_LOAD_UNIT, stdout); fputs(EV_OUTPUT_UNIT, stdout);'
                   ' return ev_selftest(); }\n')
    subprocess.run([CC, *FLAGS, str(src), "-o", str(tmp_path / "evil"), "-lm"], check=True)
    out = subprocess.run([str(tmp_path / "evil")], capture_output=True, check=True).stdout
    assert out == (evil + "|kNmV").encode("utf-8")
    # each table's comment names the output unit, mV here (it said [V] for every model)
    tables = re.findall(r"uniform intervals of \[[^]]*\] \[([^]]*)\]", header.read_text())
    assert tables and set(tables) == {"mV"}


@needs_cc
def test_two_prefixes_link_into_one_program(sample_model, rotated_model, tmp_path):
    export_header(sample_model, tmp_path / "a.h", prefix="left_")
    export_header(rotated_model, tmp_path / "b.h", prefix="right_", precision="float")
    src = tmp_path / "two.c"
    src.write_text('#define LEFT_IMPLEMENTATION\n#define RIGHT_IMPLEMENTATION\n'
                   '#include "a.h"\n#include "b.h"\n'
                   "int main(void) { return left_selftest() + right_selftest(); }\n")
    subprocess.run([CC, *FLAGS, "-O2", str(src), "-o", str(tmp_path / "two"), "-lm"], check=True)
    subprocess.run([str(tmp_path / "two")], check=True)


def test_library_errors(sample_model, tmp_path):
    with pytest.raises(ConfigError, match="expected a C identifier"):
        export_header(sample_model, tmp_path / "x.h", prefix="fsd-")
    with pytest.raises(ConfigError, match="expected one of double, float"):
        export_header(sample_model, tmp_path / "x.h", precision="half")
    with pytest.raises(FsdecoupleError, match="below what a table can reach"):
        export_header(sample_model, tmp_path / "x.h", max_error=1e-14)
    with pytest.raises(FsdecoupleError, match="the float function reaches"):
        export_header(sample_model, tmp_path / "x.h", precision="float", max_error=1e-8)
    assert not (tmp_path / "x.h").exists()


# --- the command line ---------------------------------------------------------------


def test_cli_export_writes_a_header(tmp_path):
    out = tmp_path / "decoupler.h"
    r = invoke(["export", GOLDEN / "model-v1.json", "-o", out, "--precision", "float"])
    assert "float error <=" in r.stdout and "FSD_FLOAT_MAX_ERROR" in out.read_text()
    digest = model_to_dict(load_model(GOLDEN / "model-v1.json"))["integrity"]["digest"]
    assert f'#define FSD_MODEL_DIGEST "{digest}"' in out.read_text()
    r = invoke(["export", GOLDEN / "model-v1.json", "-o", out, "--force", "--json", "--max-error", "1e-5"])
    doc = json.loads(r.stdout)
    assert doc["precision"] == "double" and 0 < doc["table_max_error"] <= 1e-5
    assert f"#define FSD_TABLE_BYTES {doc['table_bytes']}" in out.read_text()


@pytest.mark.parametrize("args, message", [
    (["--max-error", "1e-14"], "below what a table can reach"),
    (["--prefix", "1fsd"], "expected a C identifier"),
    (["--prefix", "a b"], "expected a C identifier"),
    (["--precision", "half"], "expected one of double, float"),
    (["--max-error", "-1"], "expected a positive fraction"),
])
def test_cli_export_bad_options(tmp_path, args, message):
    out = tmp_path / "decoupler.h"
    r = invoke(["export", GOLDEN / "model-v1.json", "-o", out, *args], code=2)
    assert message in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not out.exists()


@pytest.mark.parametrize("name", ["decoupler.txt", "decoupler", "model.json"])
def test_cli_export_refuses_a_suffix_that_names_no_format(tmp_path, name):
    """-o dec.txt wrote a C header: the suffix chooses the format (.cal an ATI file), so a
    suffix that names neither is refused."""
    out = tmp_path / name
    r = invoke(["export", GOLDEN / "model-v1.json", "-o", out], code=2)
    assert "expected a C header (.h, " in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_cli_export_refuses_a_corrupt_model(tmp_path):
    out = tmp_path / "decoupler.h"
    r = invoke(["export", ROOT / "tests/fixtures/bad/model-bit-flip/model.json", "-o", out], code=2)
    assert "integrity check failed" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_cli_export_keeps_an_existing_file_without_force(tmp_path):
    out = tmp_path / "decoupler.h"
    out.write_text("mine")
    r = invoke(["export", GOLDEN / "model-v1.json", "-o", out], code=2)
    assert len(r.stderr.strip().splitlines()) == 1 and out.read_text() == "mine"
    invoke(["export", GOLDEN / "model-v1.json", "-o", out, "--force"])
    assert out.read_text().startswith("/*")
    model = tmp_path / "model.json"
    shutil.copy(GOLDEN / "model-v1.json", model)
    invoke(["export", model, "-o", model, "--force"], code=2)  # never over its own input
    assert load_model(model)


def _own_status_checks(model, u, status):
    """Status bits of a six-output header against their definitions (apply reads ux..uz only)."""
    lim = np.asarray(model.extrapolation_limits())
    n = len(model.k)
    with np.errstate(invalid="ignore"):
        outside = (u < lim[:, 0]) | (u > lim[:, 1])
    bits = (status[:, None] >> np.arange(n)) & 1
    assert np.array_equal(bits == 1, outside)
    assert np.array_equal((status & INPUT_NOT_FINITE) != 0, ~np.isfinite(u).all(axis=1))
    covered = np.ones(len(u), bool)
    with np.errstate(over="ignore", invalid="ignore"):
        for c in [*model.chi.values(), *model.own.values()]:  # the own tables too
            covered &= c.surrogate.covers(u[:, c.input_axis])
    assert np.array_equal((status & OUTSIDE_TABLE) == 0, covered)


@needs_cc
def test_a_rig_model_with_own_load_chi_exports_and_matches_the_model(rig_model, tmp_path):
    """Issue 22: the joint fit's own-load chi_aa are in the header (tables and kernel sums,
    at the measured u_a), the forces within the promise of model.decouple everywhere, the
    status bits as defined; with refinement steps too, and in float within its bound."""
    model = rig_model
    run, text = build(model, tmp_path)
    n = len(model.k)
    assert f"#define FSD_N_CHI {n * n}" in text and "own-load chi_aa(u_a)" in text
    u = vectors(model, np.random.default_rng(11), 20_000)
    f_c, status = run(u)
    assert_close(f_c, decouple(model, u), model.settings.full_scale)
    _own_status_checks(model, u, status)
    # without the own chi the header's forces would be off by far more than the promise
    bare = decouple(dataclasses.replace(model, own={}), u[:1000])
    assert np.abs(bare - f_c[:1000]).max() > 1e3 * REL_FS * max(model.settings.full_scale)

    refined = dataclasses.replace(model, settings=_Settings(model.settings, refine=2))
    run, text = build(refined, tmp_path, name="refined.h")
    assert "#define FSD_REFINE_STEPS 2" in text
    lo, hi = np.asarray(model.calibrated_range).T
    inside = lo + (hi - lo) * np.random.default_rng(12).random((20_000, n))
    f_c, status = run(inside)
    assert_close(f_c, decouple(refined, inside), model.settings.full_scale)
    assert (status == 0).all()

    run, text = build(model, tmp_path, name="float.h", precision="float")
    bound = float(re.search(r"#define FSD_FLOAT_MAX_ERROR (\S+)", text).group(1))
    f_c, _ = run(inside)
    err = np.abs(f_c - decouple(model, inside.astype(np.float32).astype(float)))
    assert (err / np.asarray(model.settings.full_scale)).max() <= bound


@pytest.fixture(scope="module")
def gauge_model(tmp_path_factory):
    """Eight gauges for six components (M > N, fitting/gauges.py), with its tables."""
    from fsdecouple.data.calibration import load_calibration
    from fsdecouple.data.init_config import init_config
    from fsdecouple.sim.rig import write_rig

    out = tmp_path_factory.mktemp("gauges")
    # 4 loads a sweep (the rig's default 9) and an SVR tube of 3e-3 (Table 2's 1e-4):
    # fewer support vectors in each of the float bound's 140,000 kernel sums (10-23 a
    # chi, the own chi's too, instead of ~110: a third of the float export's CPU); the
    # projection, the tables and the kernel sums the header is checked on are the same in
    # kind, and the header is checked against this model, whatever its accuracy
    path = write_rig(out, seed=2, gauges=8, levels=4)[0]
    init_config(path, out / "cfg.yaml")
    settings = load_config(out / "cfg.yaml", epsilon=3e-3)
    model = fit(load_calibration(path, settings), settings, verdict=False)
    assert min(len(c.support_vectors) for c in [*model.chi.values(), *model.own.values()]) >= 5
    return model


@needs_cc
def test_eight_gauges_export_the_projection_and_match_the_model(gauge_model, tmp_path):
    """M > N: the header takes the eight outputs, forms v = P u and decouples it as the
    model does, within the promise; range bits on v, the rest as defined; float too."""
    model = gauge_model
    run, text = build(model, tmp_path)
    assert "#define FSD_N_OUTPUTS 8" in text and "#define FSD_N_COMPONENTS 6" in text
    assert "fsd_projection[6][8]" in text
    # each table's input is a least-squares load v_b, in its component's unit (it said [V])
    units = model.settings.units
    tables = re.findall(r"chi_(\d)(\d) on \d+ uniform intervals of \[[^]]*\] \[([^]]*)\]", text)
    assert tables and all(u == units.load_of(int(b)) for _, b, u in tables), tables
    assert {u for *_, u in tables} >= {units.load_of(0), units.load_of(5)}
    lo, hi = np.asarray(model.calibrated_range).T
    rng = np.random.default_rng(13)
    v = lo - 0.4 * (hi - lo) + 1.8 * (hi - lo) * rng.random((20_000, 6))
    u = v @ np.linalg.pinv(model.projection).T  # outputs whose least-squares loads are v
    u = np.concatenate([u, np.full((5, 8), np.nan)])
    u[-10:-5, 3] = np.nan
    f_c, status = run(u)
    assert_close(f_c, decouple(model, u), model.settings.full_scale)
    v = model.project(u)
    lim = np.asarray(model.extrapolation_limits())
    with np.errstate(invalid="ignore"):
        outside = (v < lim[:, 0]) | (v > lim[:, 1])
    assert np.array_equal(((status[:, None] >> np.arange(6)) & 1) == 1, outside)
    assert outside.any() and not outside.all(axis=1).all()
    assert np.array_equal((status & INPUT_NOT_FINITE) != 0, ~np.isfinite(u).all(axis=1))
    covered = np.ones(len(u), bool)
    with np.errstate(invalid="ignore"):
        for c in [*model.chi.values(), *model.own.values()]:
            covered &= c.surrogate.covers(v[:, c.input_axis])
    assert np.array_equal((status & OUTSIDE_TABLE) == 0, covered)

    run, text = build(model, tmp_path, name="float.h", precision="float")
    bound = float(re.search(r"#define FSD_FLOAT_MAX_ERROR (\S+)", text).group(1))
    inside = (lo + (hi - lo) * rng.random((20_000, 6))) @ np.linalg.pinv(model.projection).T
    f_c, _ = run(inside)
    err = np.abs(f_c - decouple(model, inside.astype(np.float32).astype(float)))
    assert (err / np.asarray(model.settings.full_scale)).max() <= bound


@needs_cc
@pytest.mark.parametrize("precision", ["double", "float"])
def test_a_step_added_to_the_plan_reaches_the_header(sample_model, tmp_path, monkeypatch, precision):
    """The plan's per-channel input correction (the slot of the next issue's temperature
    terms) in the model's plan: the compiled header applies it, checked against eq. (11)
    written out from the model file with the correction applied first
    (conftest.eq11_from_file).  An emitter that forgot the step would miss by 1e4 times
    the tolerance (and its self-test, computed from the plan, would fail)."""
    from conftest import eq11_from_file

    from fsdecouple.core.plan import InputCorrection

    span = np.ptp(sample_model.calibrated_range, axis=1)
    step = InputCorrection(span * np.array([0.03, -0.02, 0.025]), np.array([1.02, 0.97, 1.03]))
    real = CouplingErrorModel.plan
    monkeypatch.setattr(CouplingErrorModel, "plan", lambda self, **kw: real(self, **kw).inserted(step))
    run, text = build(sample_model, tmp_path, precision=precision)
    doc = model_to_dict(sample_model)
    lo, hi = np.asarray(sample_model.calibrated_range).T
    u = lo + (hi - lo) * np.random.default_rng(9).random((20_000, 3))
    u = u.astype(np.float32).astype(float)  # the float header's inputs are floats
    f_c, _ = run(u)
    want = eq11_from_file(doc, u, correction=(step.offset, step.gain))
    fs = np.asarray(sample_model.settings.full_scale)
    tol = REL_FS if precision == "double" else \
        2 * float(re.search(r"#define FSD_FLOAT_MAX_ERROR (\S+)", text).group(1))
    assert (np.abs(eq11_from_file(doc, u) - want) / fs).max() > 1e4 * REL_FS
    assert (np.abs(f_c - want) / fs).max() <= tol


@needs_cc
@pytest.mark.parametrize("precision", ["double", "float"])
def test_the_temperature_step_reaches_the_header(sample_model, tmp_path, precision):
    """A fitted model's temperature terms (core/temperature.py): the header takes the
    temperature as one more input, u[3], and corrects the outputs to T0 before eq. (11);
    checked against the terms written out by hand and eq. (11) from the model file.  A
    header that forgot the step would miss by 1e4 times the tolerance."""
    from dataclasses import replace as _replace

    from conftest import eq11_from_file

    from fsdecouple.core.temperature import TemperatureTerms

    span = np.ptp(sample_model.calibrated_range, axis=1)
    t0, b, g = 25.0, 1e-3 * span * np.array([1.0, -0.8, 0.6]), np.array([3e-4, -1.5e-4, 2e-4])
    model = _replace(sample_model, temperature=TemperatureTerms(3, t0, b, g, "degC", (15.0, 35.0)))
    run, text = build(model, tmp_path, precision=precision)
    assert "#define FSD_N_OUTPUTS 4" in text
    lo, hi = np.asarray(sample_model.calibrated_range).T
    rng = np.random.default_rng(12)
    u = np.column_stack([lo + (hi - lo) * rng.random((5000, 3)), rng.uniform(10, 40, 5000)])
    u = u.astype(np.float32).astype(float)
    f_c, status = run(u)
    # a temperature beyond the calibrated 15-35 degC is apply's "extrapolated", and the
    # header's bit 21 (it set no bit: the header claimed apply's status and fell short)
    beyond = (u[:, 3] < 15.0) | (u[:, 3] > 35.0)
    assert beyond.any() and (~beyond).any()
    np.testing.assert_array_equal((status.astype(np.int64) >> 21) & 1, beyond)
    assert "bit 21: the temperature u[3] is beyond the calibrated span" in text
    assert "zero-corrected outputs" not in text  # u are raw outputs and the temperature
    dt = u[:, 3:] - t0
    doc = model_to_dict(sample_model)
    want = eq11_from_file(doc, (u[:, :3] - b * dt) / (1 + g * dt))
    fs = np.asarray(sample_model.settings.full_scale)
    tol = REL_FS if precision == "double" else \
        2 * float(re.search(r"#define FSD_FLOAT_MAX_ERROR (\S+)", text).group(1))
    assert (np.abs(eq11_from_file(doc, u[:, :3]) - want) / fs).max() > 1e4 * REL_FS
    assert (np.abs(f_c - want) / fs).max() <= tol


@needs_cc
def test_the_headers_set_zero_is_the_plans_zero(sample_model, tmp_path):
    """fsd_set_zero(u_zero): the zero read at its own temperature, corrected alike and
    subtracted from each row after, as model.decouple(u, temperature=, zero=) does
    (the plan's temperature step with its zero)."""
    from dataclasses import replace as _replace

    from fsdecouple.core.temperature import TemperatureTerms

    span = np.ptp(sample_model.calibrated_range, axis=1)
    terms = TemperatureTerms(3, 25.0, 1e-3 * span * np.array([1.0, -0.8, 0.6]),
                             np.array([3e-4, -1.5e-4, 2e-4]), "degC", (15.0, 35.0))
    model = _replace(sample_model, temperature=terms)
    export_header(model, tmp_path / "d.h")
    lo, hi = np.asarray(sample_model.calibrated_range).T
    rng = np.random.default_rng(13)
    zero = np.array([*(0.05 * span), 31.0])
    u = np.column_stack([lo + (hi - lo) * rng.random((50, 3)) + zero[:3], rng.uniform(10, 40, 50)])
    rows = ", ".join("{" + ", ".join(repr(float(v)) for v in r) + "}" for r in u)
    (tmp_path / "z.c").write_text(
        '#define FSD_IMPLEMENTATION\n#include "d.h"\n#include <stdio.h>\n'
        f"static const double U[50][4] = {{{rows}}};\n"
        "int main(void) { double f[3], z[4] = {" + ", ".join(map(repr, zero.tolist())) + "};\n"
        "  int r; if (fsd_selftest() != 0) return 3; fsd_set_zero(z);\n"
        '  for (r = 0; r < 50; ++r) { fsd_decouple(U[r], f); printf("%.17g %.17g %.17g\\n", '
        "f[0], f[1], f[2]); } return 0; }\n")
    subprocess.run([CC, *FLAGS, "-O2", str(tmp_path / "z.c"), "-o", str(tmp_path / "z"), "-lm"],
                   check=True, capture_output=True, text=True)
    out = subprocess.run([str(tmp_path / "z")], check=True, capture_output=True, text=True).stdout
    f_c = np.array([[float(v) for v in line.split()] for line in out.splitlines()])
    want = model.decouple(u[:, :3], temperature=u[:, 3], zero=zero, exact=True)
    fs = np.asarray(sample_model.settings.full_scale)
    assert (np.abs(f_c - want) / fs).max() <= REL_FS
    # the zero matters: without it the forces are off by the offsets' worth
    without = model.decouple(u[:, :3], temperature=u[:, 3], exact=True)
    assert (np.abs(without - want) / fs).max() > 1e3 * REL_FS
