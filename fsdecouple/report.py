"""Rich tables built from result objects (no computation here)."""

from __future__ import annotations

from typing import Any

import numpy as np
from rich.table import Table
from rich.text import Text

from .config import AXES, FORCE_COLUMNS, VOLTAGE_COLUMNS


def pct(fraction: float | None, digits: int = 2) -> str:
    return "-" if fraction is None else f"{100.0 * fraction:.{digits}f} %"


def ingest_summary(calib, settings) -> dict[str, Any]:
    """Everything ``ingest`` reports, as plain data (also the ``--json`` document)."""
    axes = {}
    for a, axis in enumerate(AXES):
        s = calib.sweep(axis)
        grid = np.unique(s[FORCE_COLUMNS[a]].to_numpy())
        axes[axis] = {
            "points": int(len(s)),
            "points_per_repetition": {
                int(r): int(n) for r, n in s.groupby("repetition").size().items()
            },
            "load_min": float(grid.min()),
            "load_max": float(grid.max()),
            "load_levels": int(grid.size),
            "full_scale": settings.full_scale[a],
        }
    return {
        "sensor": settings.sensor,
        "files": [{"path": p, "sha256": h} for p, h in calib.files],
        "repetitions": calib.repetitions,
        "axes": axes,
        "offsets": calib.offsets.to_dict(orient="records"),
        "skipped": list(calib.skipped),
        "warnings": list(calib.warnings),
    }


def ingest_tables(summary: dict[str, Any]) -> list:
    t = Table(title=f"Calibration set: {summary['sensor']}, "
                    f"{len(summary['repetitions'])} repetitions")
    t.add_column("axis")
    t.add_column("points", justify="right")
    t.add_column("per repetition", justify="right")
    t.add_column("load grid [N]", justify="right")
    t.add_column("levels", justify="right")
    t.add_column("F.S. [N]", justify="right")
    for axis, d in summary["axes"].items():
        per = sorted(set(d["points_per_repetition"].values()))
        t.add_row(axis, str(d["points"]), "/".join(map(str, per)),
                  f"{d['load_min']:g} .. {d['load_max']:g}", str(d["load_levels"]),
                  f"{d['full_scale']:g}")
    o = Table(title="Zero offsets removed \\[mV] (mean of each sweep's zero-load rows)")
    for col in ("repetition", "axis", "zero rows", *VOLTAGE_COLUMNS):
        o.add_column(col, justify="right")
    for r in summary["offsets"]:
        o.add_row(str(r["repetition"]), r["axis"], str(r["n_zero"]),
                  *(f"{1e3 * r[c]:+.3f}" for c in VOLTAGE_COLUMNS))
    out = [t, o]
    skipped = summary["skipped"]
    out.append(Text(f"rows skipped: {len(skipped)}" + "".join(f"\n  {s}" for s in skipped)))
    return out


def fit_tables(model) -> list:
    rep = model.report
    t = Table(title=f"Non-coupling functions omega (eq. 2), sensor {model.settings.sensor}")
    for col in ("axis", "k [V/N]", "1/k [N/V] (eq. 13)", "R^2", "points"):
        t.add_column(col, justify="right")
    for a, axis in enumerate(AXES):
        r2 = rep["r2"][axis]
        r2_text = Text(f"{r2:.6f}", style="" if r2 >= model.settings.min_r2 else "bold red")
        t.add_row(axis, f"{model.k[a]:.6g}", f"{1.0 / model.k[a]:.5f}", r2_text,
                  str(rep["n_points"][axis]))
    s = model.settings.svr
    c = Table(title=f"Corrected coupling functions chi (eq. 4): eps-SVR, gamma={s.gamma:g} "
                    f"C={s.C:g} eps={s.epsilon:g} tol={s.tolerance:g}")
    for col in ("chi", "input", "support vectors", "input range [V]"):
        c.add_column(col, justify="right")
    for name, chi in model.chi.items():
        lo, hi = chi.input_range
        c.add_row(f"chi_{name}", f"u{name[1]}", f"{chi.support_vectors.size} / {chi.n_points}",
                  f"{lo:+.4f} .. {hi:+.4f}")
    g = Table(title="Interference error gamma (eq. 12) on the calibration data, % F.S.")
    for col in ("loaded axis", "before (omega^-1 only)", "after (eq. 11)"):
        g.add_column(col, justify="right")
    for axis in AXES:
        before, after = rep["gamma_before"].get(axis), rep["gamma_after"].get(axis)
        style = "bold red" if after is not None and before is not None and after > before else ""
        g.add_row(axis, pct(before), Text(pct(after), style=style))
    return [t, c, g]


def apply_lines(summary, out) -> list[str]:
    counts = ", ".join(f"{n} {name}" for name, n in summary.status_counts.items() if n)
    lines = [f"decoupled {summary.rows} rows into {out} (status: {counts})"]
    if np.any(summary.offsets):
        lines.append("zero removed [V]: " + ", ".join(
            f"{c}={v:+.6f}" for c, v in zip(VOLTAGE_COLUMNS, summary.offsets, strict=True)))
    return lines


def apply_warnings(summary) -> list[str]:
    w = []
    if summary.missing_rows:
        rows = ", ".join(map(str, summary.first_missing))
        more = ", ..." if summary.missing_rows > len(summary.first_missing) else ""
        w.append(f"{summary.missing_rows} rows have a missing voltage; kept with empty "
                 f"forces and status 'missing' (rows {rows}{more})")
    if summary.truncated_rows:
        w.append(f"row {summary.rows + 1}, the last, does not end with a newline (the writer was "
                 "cut off?); kept with empty forces and status 'truncated'")
    if summary.not_finite_rows:
        w.append(f"{summary.not_finite_rows} rows have voltages so large that eq. (11) "
                 "overflows; kept with empty forces and status 'not_finite'")
    if summary.out_of_range_rows:
        w.append(f"{summary.out_of_range_rows} rows have a voltage more than 1 % of the span "
                 "outside the calibrated range; their forces are extrapolated (status "
                 "'extrapolated')")
    return w
