"""`apply` in the data's own units: load units, output units, and raw output limits.

* One calibration logged in V, mV and ADC counts gives the same forces.
* ``--unit`` converts the forces written; Parquet records the units.
* ``limits:`` flags rows whose raw outputs reach the ADC or amplifier range
  (``saturated``), in apply and, on the same vectors, in the exported C.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from conftest import SAMPLE, invoke

# the C helpers of tests/export, also when tests/logs runs alone
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "export"))
from test_export import NOT_FINITE, SATURATED, apply_statuses, build, needs_cc, vectors

from fsdecouple import fit, load_config, load_model
from fsdecouple.config import Settings
from fsdecouple.core.modelfile import model_from_dict, model_to_dict
from fsdecouple.errors import ConfigError, InputError
from fsdecouple.logs.apply import FORCE_UNIT_KEY, OUTPUT_UNIT_KEY, STATUSES, apply_file
from fsdecouple.reporting.console import apply_warnings

LOG = SAMPLE / "task_voltages.csv"
OUTPUTS = ["ux", "uy", "uz"]
GF_IN_N = 0.00980665  # one gram-force in newtons: 1 g times standard gravity 9.80665 m/s^2
# Output unit -> factor from volts.  2**20 counts per volt is exact in binary, so the
# counts data are the very doubles of the volts data times a power of two, which
# every float operation commutes with: the fit is the same, bit for bit, up to
# that power.  1e3 is not exact (each mV value is rounded once more, ~1e-16
# relative), and the epsilon-SVR (C = 1000, libsvm stopping at a KKT tolerance)
# is that sensitive: refitting the volts data moved by one ulp moves forces by up
# to ~5e-5 of full scale, and the mV fit differs by up to ~3e-4 (a tighter solver
# tolerance does not help: 3e-4 at 1e-9, and 1e-12 runs out of iterations).
# Hence 1e-9 of full scale for counts, and for mV a bound far below any units
# mistake (a factor of 1e3) and a tenth of the paper's ~1 % interference error.
UNITS = {"V": 1.0, "mV": 1e3, "count": 2.0 ** 20}
SAME_FORCES = {"count": 1e-9, "mV": 1e-3}  # fraction of full-scale load


def _scaled_csv(src, dst, factor):
    df = pd.read_csv(src, dtype=str)
    for c in OUTPUTS:
        df[c] = [repr(float(v) * factor) for v in df[c]]
    df.to_csv(dst, index=False)


@pytest.fixture(scope="module")
def per_unit(tmp_path_factory):
    """The sample calibration and log with outputs in V, mV and counts, each fitted
    with ``scaling: full_scale`` and applied with a tare (and limits, scaled alike)."""
    log = pd.read_csv(LOG)
    # upper limits at a logged value, so some rows (2 %) reach them exactly or beyond;
    # x >= h keeps holding for x and h both multiplied by the same factor
    raw = np.sort(log[OUTPUTS].to_numpy(), axis=0)
    raw_hi = [float(v) for v in raw[int(0.98 * len(raw))]]
    out = {}
    for unit, factor in UNITS.items():
        d = tmp_path_factory.mktemp(f"unit-{unit}")
        (d / "calibration").mkdir()
        for rep in sorted((SAMPLE / "calibration").glob("*.csv")):
            _scaled_csv(rep, d / "calibration" / rep.name, factor)
        _scaled_csv(LOG, d / "log.csv", factor)
        limits = ", ".join(f"{c}: [{-10 * factor!r}, {h * factor!r}]"
                           for c, h in zip(OUTPUTS, raw_hi, strict=True))
        cfg = d / "cfg.yaml"
        cfg.write_text(f"units: {{output: {unit}}}\nscaling: full_scale\nlimits: {{{limits}}}\n")
        settings = load_config(cfg)
        # no held-out verdict: none of its figures is compared here, and on the sample
        # (svr better than the matrix) it adds no warning to compare
        model = fit(d / "calibration", settings, verdict=False)
        summary = apply_file(model, d / "log.csv", d / "f.parquet", tare=200)
        out[unit] = (model, summary, pq.read_table(d / "f.parquet"))
    return out


@pytest.mark.slow  # three fits in normalised units: seconds of CPU; the not-slow run stays under a minute
@pytest.mark.parametrize("unit", ["count", "mV"])
def test_volts_millivolts_and_counts_give_the_same_forces(per_unit, unit):
    ref_model, ref_summary, ref = per_unit["V"]
    model, summary, got = per_unit[unit]
    fs = np.asarray(ref_model.settings.full_scale)
    f_ref = np.column_stack([ref.column(c).to_numpy() for c in ("fx", "fy", "fz")])
    f = np.column_stack([got.column(c).to_numpy() for c in ("fx", "fy", "fz")])
    # counts: 1e-9 of full scale is the fast path's own promise; mV: see SAME_FORCES
    assert (np.abs(f - f_ref).max(axis=0) <= SAME_FORCES[unit] * fs).all()
    np.testing.assert_allclose(model.k, ref_model.k * UNITS[unit], rtol=1e-12)
    assert got.column("status").to_pylist() == ref.column("status").to_pylist()
    assert summary.status_counts == ref_summary.status_counts
    assert summary.status_counts["saturated"] > 0  # the limits were reached, alike in every unit
    assert apply_warnings(summary) == apply_warnings(ref_summary)
    assert model.report.warnings == ref_model.report.warnings
    np.testing.assert_allclose(summary.offsets, ref_summary.offsets * UNITS[unit], rtol=1e-12)
    assert summary.output_unit == unit and summary.force_unit == "N"
    assert got.schema.metadata[OUTPUT_UNIT_KEY.encode()] == unit.encode()


@pytest.fixture(scope="module")
def sample_model_file(sample_model):
    """conftest's sample_model: `fit` of sample_data/calibration, once a session."""
    return sample_model


def test_unit_gf_converts_the_forces(sample_model_file, tmp_path):
    n, gf, gf_csv = tmp_path / "n.parquet", tmp_path / "gf.parquet", tmp_path / "gf.csv"
    invoke(["apply", sample_model_file, LOG, "-o", n, "--tare", "200"])
    r = invoke(["apply", sample_model_file, LOG, "-o", gf, "--tare", "200", "--unit", "gf"])
    assert "forces in gf" in r.stdout
    invoke(["apply", sample_model_file, LOG, "-o", gf_csv, "--tare", "200", "--unit", "gf"])
    t_n, t_gf = pq.read_table(n), pq.read_table(gf)
    for c in ("fx", "fy", "fz"):
        # one multiplication by a rounded factor: a few ulp
        np.testing.assert_allclose(t_gf.column(c).to_numpy(), t_n.column(c).to_numpy() / GF_IN_N,
                                   rtol=1e-14)
    assert t_gf.schema.metadata[FORCE_UNIT_KEY.encode()] == b"gf"
    assert t_gf.schema.metadata[OUTPUT_UNIT_KEY.encode()] == b"V"
    assert t_n.schema.metadata[FORCE_UNIT_KEY.encode()] == b"N"
    # CSV: rounded to 1e-10 of the smallest full scale, 100 N = 10197 gf, whatever the unit
    csv = pd.read_csv(gf_csv)
    for c in ("fx", "fy", "fz"):
        err = np.abs(csv[c].to_numpy() - t_gf.column(c).to_numpy())
        assert err.max() <= 1e-10 * 100.0 / GF_IN_N
    decimals = max(len(v.split(".")[1]) for v in pd.read_csv(gf_csv, dtype=str)["fx"] if "." in v)
    assert decimals == 6  # 2e-10 x 10197 gf = 2.04e-6: six decimals; N had eight


def _kernel_choices(model, tmp_path, monkeypatch, call_work, log_work):
    """(rows, compiled) of each table-path call of apply on the sample log in blocks of
    500 rows, with the thresholds of a call (core/table_path.py COMPILED_WORK) and of a
    log (logs/apply.py APPLY_COMPILED_WORK) set; the spy runs numpy whatever is chosen."""
    from fsdecouple.core import table_path
    from fsdecouple.logs import apply as apply_module

    chosen = []
    real = table_path.TableDecoupler._couple

    def spy(self, u, workers, block_rows, covered, converged, compiled, refine):
        chosen.append((len(u), compiled))
        return real(self, u, workers, block_rows, covered, converged, False, refine)

    monkeypatch.setattr(table_path, "COMPILED_WORK", call_work)
    monkeypatch.setattr(apply_module, "APPLY_COMPILED_WORK", log_work)
    monkeypatch.setattr(table_path.TableDecoupler, "_couple", spy)
    tmp_path.mkdir()
    apply_file(model, LOG, tmp_path / "f.csv", tare=200, chunk_rows=500)
    assert len(chosen) > 3, chosen  # several blocks, each estimating the log's rows
    return chosen


def test_apply_takes_the_compiled_kernel_by_the_log_s_work(sample_model_file, tmp_path,
                                                            monkeypatch):
    """A log of APPLY_COMPILED_WORK chi evaluations or more (rows x (K + 1) x the six chi
    of the sample's model) takes the kernel in every block, a shorter one in none, even
    where a block alone would be a large call (measured: the kernel's loading costs
    apply ~0.7 s of CPU, docs/design/performance.md). Each block estimates the log's
    rows from its progress through the file, so the thresholds keep a margin of 2x."""
    model = load_model(sample_model_file)
    assert model.settings.refine == 0
    rows = len(LOG.read_text().splitlines()) - 1
    # six evaluations a row at K = 0, 24 at K = 3: a threshold of 12 a row parts them
    low = _kernel_choices(model, tmp_path / "k0", monkeypatch, 1, 12 * rows)
    assert not any(compiled for _, compiled in low), low
    high = _kernel_choices(model.refined(3), tmp_path / "k3", monkeypatch, 1 << 60, 12 * rows)
    assert all(compiled for _, compiled in high), high
    big = _kernel_choices(model, tmp_path / "big", monkeypatch, 1 << 60, 3 * rows)
    assert all(compiled for _, compiled in big), big


def test_unknown_unit_exits_2_and_writes_nothing(sample_model_file, tmp_path):
    out = tmp_path / "f.csv"
    r = invoke(["apply", sample_model_file, LOG, "-o", out, "--unit", "furlong"], code=2)
    assert "--unit 'furlong': unknown load unit" in r.stderr and "kgf" in r.stderr
    assert not out.exists() and list(tmp_path.iterdir()) == []
    with pytest.raises(InputError, match="unknown load unit"):
        apply_file(load_model(sample_model_file), LOG, out, unit="n")


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_zero_line_shows_the_output_unit(tmp_path):
    cal = tmp_path / "calibration"
    cal.mkdir()
    for rep in sorted((SAMPLE / "calibration").glob("*.csv")):
        _scaled_csv(rep, cal / rep.name, 1e3)
    _scaled_csv(LOG, tmp_path / "log.csv", 1e3)
    (tmp_path / "cfg.yaml").write_text("units: {output: mV}\n")  # scaling follows: full_scale
    m = tmp_path / "m.json"
    invoke(["fit", cal, "-o", m, "-c", tmp_path / "cfg.yaml", "--no-verdict"])  # apply's line is tested
    r = invoke(["apply", m, tmp_path / "log.csv", "-o", tmp_path / "f.csv", "--tare", "200"])
    assert "zero removed [mV]: ux=+13.8" in r.stdout  # 0.013846 V of the volts log


# --- limits and the status 'saturated' ------------------------------------------------


@pytest.mark.parametrize("text, match", [
    ("limits: {uq: [0, 1]}", "unknown key 'uq'"),
    ("limits: {ux: [1, 0]}", "ux: expected lo < hi"),
    ("limits: {ux: [1, 1]}", "ux: expected lo < hi"),
    ("limits: {ux: [0, .inf]}", "ux: expected a finite number"),
    ("limits: {ux: [0, 1, 2]}", r"ux: expected \[lo, hi\]"),
    ("limits: {ux: 5}", r"ux: expected \[lo, hi\]"),
    ("limits: [0, 1]", "limits: expected a mapping"),
])
def test_bad_limits_are_refused(tmp_path, text, match):
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text(text + "\n")
    with pytest.raises(ConfigError, match=match):
        load_config(cfg)


def test_bad_limits_exit_2_in_apply(sample_model_file, tmp_path):
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("limits: {uy: [2, -2]}\n")
    r = invoke(["apply", sample_model_file, LOG, "-o", tmp_path / "f.csv", "-c", cfg], code=2)
    assert "limits: uy: expected lo < hi" in r.stderr
    assert not (tmp_path / "f.csv").exists()


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_limits_round_trip_through_the_model_file(tmp_path):
    assert "limits" not in Settings().to_dict()  # files without limits keep their bytes
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("limits: {ux: [-2.5, 2.5], uz: [-10, 0.25]}\n")
    settings = load_config(cfg)
    assert settings.limits == {"ux": (-2.5, 2.5), "uz": (-10.0, 0.25)}
    m = tmp_path / "m.json"
    invoke(["fit", SAMPLE / "calibration", "-o", m, "-c", cfg, "--no-verdict"])  # the settings are tested
    model = load_model(m)
    assert model.settings.limits == settings.limits
    assert model_from_dict(model_to_dict(model)).settings == model.settings


SAT_LOG = """t,ux,uy,uz
0,0.10,0.00,-0.50
1,1.00,0.00,-0.50
2,1.20,0.00,-0.50
3,0.10,-1.00,-0.50
4,0.10,0.00,
5,nan,1.00,-0.50
6,0.99999,0.00,-0.50
7,0.10,0.00,-1.45
8,0.10,0.00,-1.60
"""
# ux at its limit (1), beyond it, uy at its lower limit (-1), empty and NaN rows
# (missing, even with uy at its limit), just inside, uz outside the calibrated range
# (about -1.2 .. 0 V) but inside its limit, and beyond it.
SAT_STATUS = ["ok", "saturated", "saturated", "saturated", "missing", "missing", "ok",
              "extrapolated", "saturated"]


def test_saturated_rows_in_csv_and_parquet(sample_model_file, tmp_path):
    log, cfg = tmp_path / "log.csv", tmp_path / "cfg.yaml"
    log.write_text(SAT_LOG)
    cfg.write_text("limits: {ux: [-1, 1], uy: [-1, 1], uz: [-1.5, 0.5]}\n")
    fc, fp = tmp_path / "f.csv", tmp_path / "f.parquet"
    r = invoke(["apply", sample_model_file, log, "-o", fc, "-c", cfg])
    assert "4 saturated" in r.stdout and "2 missing" in r.stdout
    assert "4 rows have an output at or beyond its limit" in r.stderr
    invoke(["apply", sample_model_file, log, "-o", fp, "-c", cfg])
    csv = pd.read_csv(fc, dtype={"status": str}, keep_default_na=False)
    par = pq.read_table(fp).to_pandas()
    assert csv["status"].tolist() == par["status"].tolist() == SAT_STATUS
    assert set(SAT_STATUS) <= set(STATUSES)
    for c in ("fx", "fy", "fz"):
        # saturated rows keep their forces, missing rows have none
        has = par["status"] != "missing"
        assert par.loc[has, c].notna().all() and par.loc[~has, c].isna().all()
        np.testing.assert_allclose(pd.to_numeric(csv.loc[has, c]), par.loc[has, c], rtol=0,
                                   atol=1e-10 * 100)


def test_only_the_limited_output_saturates(sample_model_file, tmp_path):
    """Limits on uy alone: uy at -1 saturates its row; ux at and beyond 1 does not (its
    column has no limits, so apply does not scan it: RowRules.limited)."""
    log, cfg, out = tmp_path / "log.csv", tmp_path / "cfg.yaml", tmp_path / "f.csv"
    log.write_text(SAT_LOG)
    cfg.write_text("limits: {uy: [-1, 1]}\n")
    invoke(["apply", sample_model_file, log, "-o", out, "-c", cfg])
    status = pd.read_csv(out, dtype={"status": str}, keep_default_na=False)["status"].tolist()
    assert status[3] == "saturated" and "saturated" not in status[:3] + status[6:], status


def test_limits_compare_the_raw_values_before_the_zero(sample_model_file, tmp_path):
    """--zero shifts u after the limits are checked: raw 1.0 saturates, raw 0.95 does not."""
    log = tmp_path / "log.csv"
    log.write_text("ux,uy,uz\n1.0,0,-0.5\n0.95,0,-0.5\n")
    model = load_model(sample_model_file)
    model = dataclasses.replace(model, settings=dataclasses.replace(
        model.settings, limits={"ux": (-1.0, 1.0)}))
    out = tmp_path / "f.parquet"
    apply_file(model, log, out, zero=(0.5, 0.0, 0.0))  # the model's own limits
    assert pq.read_table(out).column("status").to_pylist() == ["saturated", "ok"]
    apply_file(model, log, out, zero=(-0.1, 0.0, 0.0), force=True)
    # zero-corrected 1.05 lies beyond the limit, raw 0.95 does not (and 1.05 V is
    # inside ux's calibrated range, about +-1.33 V)
    assert pq.read_table(out).column("status").to_pylist() == ["saturated", "ok"]


def test_config_limits_take_precedence_over_the_models(sample_model_file, tmp_path):
    log = tmp_path / "log.csv"
    log.write_text("ux,uy,uz\n0.5,0,-0.5\n")
    model = load_model(sample_model_file)
    model = dataclasses.replace(model, settings=dataclasses.replace(
        model.settings, limits={"ux": (-0.5, 0.5)}))
    out = tmp_path / "f.parquet"
    apply_file(model, log, out)
    assert pq.read_table(out).column("status").to_pylist() == ["saturated"]
    wide = dataclasses.replace(model.settings, limits={"ux": (-2.0, 2.0)})
    apply_file(model, log, out, settings=wide, force=True)
    assert pq.read_table(out).column("status").to_pylist() == ["ok"]


@pytest.mark.slow  # over ~0.8 s: the not-slow run stays under a minute
@needs_cc
def test_apply_and_c_saturation_agree_without_a_tare(tmp_path, sample_model):
    """The C compares the values passed in, apply the raw ones: the same without a tare."""
    base = load_model(sample_model)  # the suite's sample fit
    lo, hi = np.asarray(base.calibrated_range).T
    span = hi - lo
    limits = {"ux": (lo[0] - 0.2 * span[0], hi[0] + 0.2 * span[0]),
              "uz": (lo[2] - 0.5 * span[2], hi[2] + 0.1 * span[2])}
    model = dataclasses.replace(base, settings=dataclasses.replace(base.settings, limits=limits))
    run, text = build(model, tmp_path)  # limits from model.settings.limits
    assert "saturated at u[0] <=" in text and "u[1] <=" not in text
    rng = np.random.default_rng(3)
    u = vectors(model, rng, n_random=20_000)
    edges = []
    for b, key in ((0, "ux"), (2, "uz")):
        for x in limits[key]:
            for y in (np.nextafter(x, -np.inf), x, np.nextafter(x, np.inf)):
                row = lo + span * rng.random((10, 3))
                row[:, b] = y
                edges.append(row)
    u = np.concatenate([u, *edges])
    _, status = run(u)
    want = np.full(len(u), "ok", dtype=object)
    want[(status & 0b111) != 0] = "extrapolated"
    want[(status & SATURATED) != 0] = "saturated"
    want[(status & NOT_FINITE) != 0] = "not_finite"
    want[np.isnan(u).any(axis=1)] = "missing"
    got = apply_statuses(model, u, tmp_path)
    assert (got == want).all()
    assert (got == "saturated").sum() > 1000


def test_a_config_in_other_units_than_the_model_is_refused(tmp_path, sample_model):
    """A log in counts read with a model fitted in volts would be off by orders of magnitude."""
    model = sample_model  # fitted in volts (conftest)
    cfg = tmp_path / "counts.yaml"
    cfg.write_text("units: {load: N, output: count}\n")
    out = tmp_path / "f.csv"
    r = invoke(["apply", model, SAMPLE / "task_voltages.csv", "-c", cfg, "-o", out], code=2)
    assert "not the model's" in r.stderr and not out.exists()
