"""Every rich table and console line the commands print (sqlfluff's ``formatters.py``).

Built from result objects and documents; no computation here beyond picking
numbers out of them.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any

import numpy as np
from rich import box
from rich.table import Table
from rich.text import Text

from ..axes import labels_in, load_name
from ..core.metrics import pct
from ..data.guesses import Guess
from ..data.guesses import shown as shown_name
from ..errors import printable
from ..evaluation.cv_results import REFINED, gamma_index, scored_axes, test_name
from ..fitting.joint import JOINT_C
from ..units import Units, output_display
from .narrow import KEY_COLUMNS
from .temperature_tables import temperature_tables
from .words import counted, output_unit_of, svr_unit

# --- ingest, fit, show, apply ------------------------------------------------------


def _units(settings_or_doc) -> Units:
    u = getattr(settings_or_doc, "units", None)
    if isinstance(u, Units):
        return u
    if not isinstance(settings_or_doc, dict):
        return Units()
    u = settings_or_doc.get("units", {})
    return Units(**{k: (" / ".join(dict.fromkeys(v.values())) if isinstance(v, dict) else v)
                    for k, v in u.items()})


def ingest_tables(summary: dict[str, Any]) -> list:
    units = _units(summary)
    t = Table(title=f"Calibration set: {summary['sensor']}, "
                    f"{counted(len(summary['repetitions']), 'repetition')}")
    t.add_column("axis")
    t.add_column("points", justify="right")
    t.add_column("per repetition", justify="right")
    t.add_column(f"load grid [{units.load}]", justify="right")
    t.add_column("levels", justify="right")
    t.add_column(f"F.S. [{units.load}]", justify="right")
    for axis, d in summary["axes"].items():
        per = sorted(set(d["points_per_repetition"].values()))
        t.add_row(axis, str(d["points"]), "/".join(map(str, per)),
                  f"{d['load_min']:g} .. {d['load_max']:g}", str(d["load_levels"]),
                  f"{d['full_scale']:g}")
    factor, shown = output_display(units.output)
    how = ("fitted to all of each sweep's points, zero: fit" if summary.get("zero") == "fit"
           else "mean of each sweep's zero-load rows")
    o = Table(title=f"Zero offsets removed [{shown}] ({how})")
    outputs = [c for c in (summary["offsets"] or [{}])[0] if c not in ("repetition", "axis",
                                                                        "n_zero")]
    for col in ("repetition", "axis", "zero rows", *outputs):
        o.add_column(col, justify="right")
    digits = 1 if shown == "count" else 3  # a mean of a few readings of whole counts
    for r in summary["offsets"]:
        o.add_row(str(r["repetition"]), r["axis"], str(r["n_zero"]),
                  *(f"{factor * r[c]:+.{digits}f}" for c in outputs))
    out = [t, o]
    skipped = summary["skipped"]
    out.append(Text(f"rows skipped: {len(skipped)}" + "".join(f"\n  {s}" for s in skipped)))
    return out


def imported_tables(model) -> list:
    """An imported factory matrix (data/ati_cal.py): f = C u, full scale, temperature terms."""
    units, layout = model.settings.units, model.layout
    t = Table(title=f"Factory calibration matrix f = C u, sensor {model.settings.sensor} "
                    "(imported; decoupled as ATIDAQ does)")
    t.add_column("component", justify="right")
    t.add_column("full scale", justify="right")
    for o in layout.outputs:
        t.add_column(f"{o} [load/{units.output_of(0)}]", justify="right")
    for a, axis in enumerate(layout.labels):
        t.add_row(f"{axis} [{units.load_of(a)}]", f"{model.settings.full_scale[a]:g}",
                  *(f"{v:.6g}" for v in model.matrix[a]))
    out = [t]
    temp = model.temperature
    if temp is not None:
        c = Table(title=f"Temperature terms: u(T0) = (u - b (T - T0)) / (1 + g (T - T0)), "
                        f"T = {layout.outputs[temp.channel]}, T0 = {temp.t0:g} {temp.unit}")
        for col in ("output", f"b [{units.output_of(0)}/{temp.unit}]", f"g [1/{temp.unit}]"):
            c.add_column(col, justify="right")
        for i, o in enumerate(layout.outputs):
            if i != temp.channel:
                c.add_row(o, f"{temp.b[i]:+.6g}", f"{temp.g[i]:+.6g}")
        out.append(c)
    return out


def zero_used(model) -> str:
    """How the fit zeroed its outputs: ``intercept`` where the model holds fitted offsets,
    the zero row before each row on rows loading several components (fitting/fit.py's
    provenance), else the settings' (``fit`` on sweeps out and back, evaluation/calibrate.py);
    a set makes the first two choices itself where the config leaves zero unsaid."""
    if getattr(model, "zero", None) is not None:
        return "intercept"
    if (model.provenance or {}).get("zero") == "before":
        return "each row's nearest zero row before it"
    return model.settings.zero_method


def fit_tables(model) -> list:
    if getattr(model, "imported", False):
        return imported_tables(model)
    rep = model.report
    units = model.settings.units
    volts = units == Units()  # the paper's figures keep their paper-like format
    t = Table(title=("Least-squares loads v = P u of M > N outputs (docs/rigs.md)" if getattr(
        model, "projection", None) is not None else "Non-coupling functions omega (eq. 2)")
        + f", sensor {model.settings.sensor}")
    # forces and moments, or outputs in several units: each row says its own units, as
    # the report does (a header 'k [N / N·m/load]' said none)
    mixed = bool(units.loads or units.outputs)
    projected = getattr(model, "projection", None) is not None  # v = P u, in the loads' units
    layout = model.layout
    heads = ("k", "1/k (eq. 13)") if mixed or projected else (
        f"k [{units.slope()}]", f"1/k [{units.inverse_slope()}] (eq. 13)")
    for col in ("axis", *heads, "R^2", "points"):
        t.add_column(col, justify="right")
    for a, axis in enumerate(layout.labels):
        r2 = rep.r2[axis]
        r2_text = Text(f"{r2:.6f}", style="" if r2 >= model.settings.min_r2 else "bold red")
        inverse = f"{1.0 / model.k[a]:.5f}" if volts else f"{1.0 / model.k[a]:.6g}"
        k = f"{model.k[a]:.6g}"
        if mixed and not projected:  # k of eq. (2): component a's prime output per its load
            out, load = units.output_of(a), units.load_of(a)
            k, inverse = f"{k} {out}/{load}", f"{inverse} {load}/{out}"
        t.add_row(f"{axis} [{units.load_of(a)}]" if mixed else axis, k, inverse,
                  r2_text, str(rep.n_points[axis]))
    s = model.settings.svr
    # rows loading several components or more gauges than loads: fitted jointly, with C
    # and epsilon of their own (fitting/joint.py), which the table says rather than Table 2's
    joint = bool(getattr(model, "own", None)) or projected
    # libsvm's gamma, epsilon and tolerance are in the chi's own units: full-scale outputs
    # (scaling: full_scale) or the outputs' unit
    u = svr_unit(model.settings.scaling, units.output, full_scale=joint)
    svr = (f"C={JOINT_C:g} eps=each output's noise sigma (at least {s.epsilon:g}), fitted "
           "jointly" if joint else f"C={s.C:g} eps={s.epsilon:g}")
    c = Table(title=f"Corrected coupling functions chi (eq. 4): eps-SVR in {u}, "
                    f"gamma={s.gamma:g} {svr} tol={s.tolerance:g}",
              caption=f"beyond the input range: {model.settings.extrapolation} (extrapolation); "
                      f"zero offsets: {zero_used(model)}; refinement steps K = "
                      f"{model.settings.refine}")
    gauges = projected  # M > N: inputs v = P u (gauges.py)
    each = gauges and bool(units.loads) or not gauges and bool(units.outputs)  # a unit per row
    shown = "" if each else f" [{'load' if gauges else units.output}]"
    for col in ("chi", "input", "support vectors", f"input range{shown}"):
        c.add_column(col, justify="right")
    span = "{:+.4f} .. {:+.4f}" if volts else "{:+.6g} .. {:+.6g}"
    # a joint fit's own-load chi_aa too (fitting/joint.py: chi_own in the model file)
    for name, chi in {**model.chi, **(getattr(model, "own", None) or {})}.items():
        b = chi.input_axis
        unit = f" {units.load_of(b) if gauges else units.output_of(b)}" if each else ""
        c.add_row(f"chi_{name}", f"{layout.labels[b]}_ls" if gauges else layout.outputs[b],
                  f"{chi.support_vectors.size} / {chi.n_points}",
                  span.format(*chi.input_range) + unit)
    if gauges:  # each chi of a load sums the gauges' own (gauges.py): more vectors than points
        c.caption += (f"; support vectors / points: a chi of the loads merges the "
                      f"{model.n_outputs} gauges' SVRs, so it holds more vectors than the points "
                      "each was fitted on")
    linear = getattr(model, "method", "svr") == "linear"  # decouples by the matrix f = C u
    g = Table(title="Interference error gamma (eq. 12) on the calibration data, % F.S."
              + ("; the model decouples by the least-squares calibration matrix" if linear else ""))
    for col in ("loaded axis", "before (omega^-1 only)",
                "after (the matrix f = C u)" if linear else "after (eq. 11)"):
        g.add_column(col, justify="right")
    for axis in layout.labels:
        before, after = rep.gamma_before.get(axis), rep.gamma_after.get(axis)
        style = "bold red" if after is not None and before is not None and after > before else ""
        g.add_row(axis, pct(before), Text(pct(after), style=style))
    return [t, c, g, *temperature_tables(model)]


def apply_lines(summary, out) -> list[str]:
    counts = ", ".join(f"{n} {name}" for name, n in summary.status_counts.items() if n)
    rows = f"{summary.rows} row{'' if summary.rows == 1 else 's'}"
    lines = [f"decoupled {rows} into {printable(out)} (forces in {summary.force_unit}; "
             f"status: {counts})"]
    if np.any(summary.offsets):
        pairs = list(zip(summary.outputs, summary.offsets, strict=True))
        t_unit = getattr(summary, "temperature_unit", None)
        outputs = pairs[:-1] if t_unit else pairs  # a fitted model's temperature comes last
        lines.append(f"zero removed [{summary.output_unit}]: " + ", ".join(
            f"{c}={v:+.6f}" for c, v in outputs)
            + (f"; read at {pairs[-1][1]:.6g} {t_unit} ({pairs[-1][0]})" if t_unit else ""))
    return lines


SHOWN_COLUMNS = 20  # dropped log columns named in apply's warning; the rest counted


def _rows(n: int) -> str:
    """``1 row has`` / ``3 rows have``, a warning's start."""
    return f"{n:,} row has" if n == 1 else f"{n:,} rows have"


def apply_warnings(summary) -> list[str]:
    w, groups = list(getattr(summary, "notes", ())), {}
    for d in getattr(summary, "dropped", ()):
        groups.setdefault(d.reason, []).append(f"{d.column} '{d.name}'" if d.name else str(d.column))
    if groups:  # a few named: a log of 200,000 side columns made one 2 MB line
        w.append("log columns not passed through (fit ignores them too): " + "; ".join(
            f"{', '.join(cols[:SHOWN_COLUMNS])}"
            f"{f' and {len(cols) - SHOWN_COLUMNS:,} more' if len(cols) > SHOWN_COLUMNS else ''}"
            f" ({reason})" for reason, cols in groups.items()))
    if summary.missing_rows:
        rows = ", ".join(map(str, summary.first_missing))
        more = ", ..." if summary.missing_rows > len(summary.first_missing) else ""
        w.append(f"{_rows(summary.missing_rows)} a missing voltage; kept with empty "
                 f"forces and status 'missing' (row{'s' if summary.missing_rows > 1 else ''} "
                 f"{rows}{more})")
    if summary.truncated_rows:
        w.append(f"row {summary.rows + 1}, the last, does not end with a newline (the writer was "
                 "cut off?); kept with empty forces and status 'truncated'")
    if summary.not_finite_rows:
        w.append(f"{_rows(summary.not_finite_rows)} forces that overflow or pass 1e6 x "
                 "full scale (voltages far too large, or a broken model); kept with empty "
                 "forces and status 'not_finite'")
    if summary.saturated_rows:
        w.append(f"{_rows(summary.saturated_rows)} an output at or beyond its limit "
                 "(limits:), so the channel may have clipped; their forces are written "
                 "but flagged (status 'saturated')")
    if summary.out_of_range_rows:
        temperature = "temperature" in summary.outputs  # a fitted model's (issue 31)
        w.append(f"{_rows(summary.out_of_range_rows)} a voltage more than 1 % of the span "
                 "outside the calibrated range" + (", or a temperature outside the calibrated "
                                                   "temperatures" if temperature else "")
                 + f"; {'its forces are' if summary.out_of_range_rows == 1 else 'their forces are'}"
                 " extrapolated (status 'extrapolated')")
    if getattr(summary, "untared", None):
        out, median, lo, hi = summary.untared
        unit = summary.output_unit
        # "typically": the median of each block's median, over a sample of a long block's
        # rows (untared.py), not the exact median of every row
        w.append(f"most rows ({summary.out_of_range_rows} of {summary.rows}) lie outside the "
                 f"calibrated range by about a constant offset ({out}: typically {median:.6g} "
                 f"{unit}, calibrated {lo:.6g} to {hi:.6g} {unit}): the log looks unzeroed; "
                 "give --tare N (its first N rows unloaded) or --zero")
    if summary.status_counts.get("not_converged"):
        w.append(f"{summary.status_counts['not_converged']} rows did not settle in the "
                 "second-order refinement (refine: K); kept with empty forces and status "
                 "'not_converged'")
    return w


# --- cv -----------------------------------------------------------------------------

WORSE = "bold red"  # Table 1 sets cells worse than the initial data in bold


def _num(fraction: float) -> str:
    return f"{100.0 * fraction:.2f}"


def gamma_table(doc: dict[str, Any], records=None, title=None, clean=None) -> Table:
    """Tables 1 and 3 side by side: rows round x test set, a column group per method.

    A cell worse than the initial data of the same round, test set and axis is
    bold red, as Table 1 sets them in bold.  With ``clean`` records (Table 5), a
    cell that differs from its clean value carries a ``*``.
    """
    idx = gamma_index(doc["records"] if records is None else records)
    ref = gamma_index(clean) if clean is not None else None
    levels = doc.get("protocol") == "levels"
    poses = doc.get("protocol") == "poses"
    held = "load levels (interior points)" if levels else "poses" if poses else "repetitions"
    t = Table(title=title or f"Interference error gamma (eq. 12) on held-out {held}, % F.S. "
                             "(! and bold red: worse than initial)", box=box.SIMPLE_HEAD,
              pad_edge=False, padding=(0, 0, 0, 1))
    t.add_column("round", no_wrap=True)
    t.add_column("test (level)" if levels else "test (fold)" if poses else "test (rep)",
                 no_wrap=True)
    setattr(t, KEY_COLUMNS, 2)  # a narrow terminal's parts repeat round and test (narrow.py)
    cell_width = 5 if ref is not None else 4
    axes = scored_axes(doc, records)
    for m in doc["methods"]:
        for a in axes:
            # the method names its column group once, over its first gamma column
            t.add_column(f"{m if a == axes[0] else ''}\nγ{a}", justify="right", no_wrap=True,
                         min_width=max(len(m), cell_width) if a == axes[0] else cell_width)
    for r, fold in enumerate(doc["folds"], start=1):
        for i, rep in enumerate(fold):
            cells = []
            for m in doc["methods"]:
                for a in axes:
                    v = idx.get((r, rep, m, a))
                    if v is None:  # no held-out point of this axis in the round
                        cells.append(Text("-"))
                        continue
                    worse = m != "initial" and v > idx[(r, rep, "initial", a)]
                    mark = "*" if ref is not None and ref.get((r, rep, m, a)) != v else ""
                    # "!" keeps the paper's bold visible in plain-text CI logs
                    cells.append(Text(_num(v) + mark + ("!" if worse else ""),
                                      style=WORSE if worse else ""))
            name = f"poses {rep}, {rep + 5}, ..." if poses else f"{test_name(i)} ({rep})"
            t.add_row(str(r) if i == 0 else "", name, *cells)
        if r < len(doc["folds"]):
            t.add_section()
    return t


def summary_lines(doc: dict[str, Any]) -> list[str]:
    worst = defaultdict(float)
    worse = defaultdict(int)
    base = gamma_index(doc["records"])
    for rec in doc["records"]:
        m = rec["method"]
        worst[m] = max(worst[m], rec["value"])
        if m != "initial" and rec["value"] > base[(rec["round"], rec["test_set"], "initial",
                                                   rec["axis"])]:
            worse[m] += 1
    n = len([r for r in doc["records"] if r["method"] == "initial"])
    w = max(9, *map(len, doc["methods"]))
    lines = [f"{m:{w}s} worst gamma {_num(worst[m]):>6s} % F.S."
             + ("" if m == "initial" else f", {worse[m]} of {n} cells worse than initial")
             for m in doc["methods"]]
    if doc.get("protocol") == "levels":
        lines.insert(0, "protocol: levels (round k holds out the k-th loaded point of every sweep; "
                        "points beyond the loads left in their sweep are end points, scored apart)")
        end = defaultdict(float)
        for rec in doc.get("end_records", []):
            end[rec["method"]] = max(end[rec["method"]], rec["value"])
        lines += [f"{m:{w}s} worst gamma {_num(end[m]):>6s} % F.S. on end points (extrapolation)"
                  for m in doc["methods"] if m in end]
    elif doc.get("protocol") == "poses":
        lines.insert(0, "protocol: poses (round k of 5 holds out every fifth pose in file order, "
                        "from the k-th)")
    else:
        lines.insert(0, "protocol: repetitions (each round holds out whole repetitions, Section 4.1)")
    if doc.get("refine"):
        k = (doc.get("settings") or {}).get("refine") or 0
        lines.append(f"{REFINED}: the svr models with K = {doc['refine']} second-order "
                     f"refinement steps (eqs. 5-6); svr: K = {k}, the config's")
    return lines


def task_table(doc: dict[str, Any]) -> Table:
    """Combined-load errors per method: worst round's max and RMS error, % F.S."""
    task = doc["task"]
    tare = f", tare {task['tare']} rows" if task["tare"] else ", no tare"
    t = Table(title=f"Combined loads: {task['voltages']} ({task['rows']} rows{tare}) against "
                    "true forces; error % F.S., worst round (!: over 10x the best method's)")
    t.add_column("method")
    axes = labels_in(task["records"])
    for metric in ("max", "RMS"):
        for a in axes:
            t.add_column(f"{metric if a == axes[0] else ''}\n|Δ{load_name(a)}|", justify="right")
    worst: dict[tuple, float] = defaultdict(float)
    for rec in task["records"]:
        key = (rec["method"], rec["metric"], rec["axis"])
        worst[key] = max(worst[key], rec["value"])
    best = min(worst[(m, "max_error", a)] for m in doc["methods"] for a in axes)
    for m in doc["methods"]:
        cells = []
        for metric in ("max_error", "rms_error"):
            for a in axes:
                v = worst[(m, metric, a)]
                # an error above 10x the best method's is an explosion worth seeing
                explodes = v > 10 * max(best, 1e-12)
                cells.append(Text(_num(v) + ("!" if explodes else ""),
                                  style=WORSE if explodes else ""))
        t.add_row(m, *cells)
    return t


def mimo_note(doc: dict[str, Any]) -> str | None:
    """Say why the black-box network's combined-load error can be huge (it is the paper's point)."""
    recs = [r for r in doc["task"]["records"] if r["metric"] == "max_error"]
    mimo = max((r["value"] for r in recs if r["method"] == "rbf-mimo"), default=None)
    svr = max((r["value"] for r in recs if r["method"] == "svr"), default=None)
    if mimo is None or svr is None or mimo <= 10 * max(svr, 1e-12):
        return None
    return (f"rbf-mimo: {_num(mimo)} % F.S. on combined loads. The black-box network learned "
            "only the single-axis calibration points and extrapolates freely off them; the "
            "coupling error model needs no combined-load data (the paper's point, Section 4).")


def gross_tables(doc: dict[str, Any]) -> list[Table]:
    """Table 5 (svr with and without the moved point) and eq. (13) vs eq. (14)."""
    g = doc["gross_error"]
    s = g["spec"]
    t = gamma_table(
        doc, g["records"], clean=doc["records"],
        title=f"Table 5: gamma % F.S. with point {s['point']} of the {s['axis']} sweep of "
              f"repetition {s['repetition']} moved by {s['offset']:+g} {output_unit_of(doc)} in "
              "the training data "
              "(*: changed from the clean run)")
    side = Table(title="svr: Table 3 (clean) beside Table 5 (moved point), % F.S.",
                 box=box.SIMPLE_HEAD, pad_edge=False)
    side.add_column("round")
    side.add_column("test (rep)")
    axes = scored_axes(doc)
    for label in ("clean", "moved"):
        for a in axes:
            side.add_column(f"{label if a == axes[0] else ''}\nγ{a}", justify="right")
    side.add_column("largest\nchange", justify="right")
    clean, moved = gamma_index(doc["records"]), gamma_index(g["records"])
    for r in g["rounds_affected"]:
        for i, rep in enumerate(doc["folds"][r - 1]):
            c = [clean[(r, rep, "svr", a)] for a in axes]
            m = [moved[(r, rep, "svr", a)] for a in axes]
            change = max(abs(x - y) for x, y in zip(c, m, strict=True))
            side.add_row(str(r) if i == 0 else "",
                         f"{test_name(i)} ({rep})",
                         *(_num(v) for v in c + m), _num(change))
    o = Table(title="omega^-1 [N/V]: clean (eq. 13) vs with the gross error (eq. 14)")
    for col in ("round", "axis", "clean", "gross", "change"):
        o.add_column(col, justify="right")
    for rec in g["omega"]:
        if rec["k_clean"] == rec["k_gross"]:
            continue
        o.add_row(str(rec["round"]), rec["axis"], f"{rec['inverse_clean']:.3f}",
                  f"{rec['inverse_gross']:.3f}",
                  f"{100 * (rec['inverse_gross'] / rec['inverse_clean'] - 1):+.2f} %")
    return [t, side, o]


def fit_checks_table(checks) -> Table:
    """Section 2.1 assumption checks of a fitted model (the ones the report shows)."""
    return checks_table({"checks": [{**c.to_dict(), "round": 1} for c in checks]},
                        title="Assumption checks (Section 2.1) of the model", column="value")


def checks_table(doc: dict[str, Any], title: str = "Assumption checks (Section 2.1) of each "
                 "round's svr model", column: str = "round {r}") -> Table:
    """Section 2.1 assumption checks of each round's svr model."""
    rounds = sorted({c["round"] for c in doc["checks"]})
    t = Table(title=title)
    t.add_column("check")
    t.add_column("subject")
    t.add_column("limit", justify="right")
    for r in rounds:
        t.add_column(column.format(r=r), justify="right")
    t.add_column("status")
    rows: dict[tuple, dict] = {}
    for c in doc["checks"]:
        rows.setdefault((c["name"], c["subject"], c["limit"]), {})[c["round"]] = c
    fmt = {"linearity": "{:.5f}", "coupling": "{:.2%}", "slope": "{:.4f}",
           "second_order": "{:.3%}"}
    for (name, subject, limit), by_round in rows.items():
        f = fmt.get(name, "{:.4g}")
        sign = ">=" if name == "linearity" else "<="
        status = "pass" if all(c["status"] == "pass" for c in by_round.values()) else "warning"
        t.add_row(name, subject, f"{sign} {f.format(limit)}",
                  *(f.format(by_round[r]["value"]) if r in by_round else "-" for r in rounds),
                  Text(status, style="" if status == "pass" else "yellow"))
    return t


def timing_table(doc: dict[str, Any]) -> Table:
    tm = doc["timing"]
    v = {(r["method"], r["metric"]): r["value"] for r in tm["records"]}
    t = Table(title=f"Timing (Table 4): medians over rounds and {tm['repeats']} sequential pass(es)")
    for col in ("method", "establishment [ms]", "decoupling one vector [µs]"):
        t.add_column(col, justify="right")
    for m in doc["methods"]:
        t.add_row(m, f"{1e3 * v[(m, 'establish_seconds')]:.1f}",
                  f"{1e6 * v[(m, 'decouple_seconds_per_vector')]:.1f}")
    return t


def parallel_line(doc: dict[str, Any]) -> str:
    p = doc["timing"]["parallel"]
    return (f"training: {p['wall_seconds']:.2f} s on {p['workers']} threads, "
            f"about {p['sequential_seconds']:.2f} s sequential (estimated from Table 4's "
            f"sample; speed-up {p['speedup']:.2f}x)")


def cv_renderables(doc: dict[str, Any]) -> list:
    """Everything ``fsdecouple cv`` prints, in order."""
    out: list = [gamma_table(doc), Text("\n".join(summary_lines(doc)))]
    if doc["task"] is not None:
        out.append(task_table(doc))
        note = mimo_note(doc)
        if note:
            out.append(Text(note))
    if doc["gross_error"] is not None:
        out += gross_tables(doc)
    out += [checks_table(doc), timing_table(doc), Text(parallel_line(doc))]
    if doc["gate"] is not None:
        g = doc["gate"]
        out.append(Text(f"gate: worst svr gamma {_num(g['worst'])} % F.S. "
                        f"{'<=' if g['passed'] else '>'} --max-gamma {_num(g['max_gamma'])} % "
                        f"-> {'passed' if g['passed'] else 'FAILED'}",
                        style="" if g["passed"] else "bold red"))
    return out


# --- init -----------------------------------------------------------------------------

def guess_renderables(guess: Guess) -> list:
    """What ``init`` prints: a table (key, column, reason), the notes, where the config
    went.  File text (header names, paths) is shown literally, never as rich markup."""
    t = Table("key", "column", "reason", title=Text(f"Guessed from {guess.path}"))
    for key in guess.keys:
        t.add_row(key, Text(guess.columns.get(key, "-")), Text(guess.reasons[key]))
    for key, value, why in guess.settings():
        t.add_row(key, Text(value), Text(why))
    for i in guess.ignored:
        t.add_row("(ignored)", Text(f"{i.column}: {shown_name(i.name)}"), Text(i.reason))
    notes = [Text.assemble(("note:", "yellow"), f" {n}") for n in guess.notes]
    done = f"config written to {printable(guess.config)}; check every guessed value before fitting"
    return [t, *notes, Text(done)]
