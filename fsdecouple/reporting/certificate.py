"""The certificate a lab signs: one self-contained HTML page that prints on A4, and
the terminal's tables, both from the ``fsdecouple.certificate`` document
(:func:`fsdecouple.evaluation.certificate.certificate`)."""

from __future__ import annotations

from html import escape

from matplotlib.figure import Figure
from rich.table import Table

from .html import CSS, cell, figure_html, note, table, th, tr
from .plots import to_png

METRIC_NAMES = {"b": "b [%]", "b_prime": "b′ [%]", "f_c": "f_c [%]", "f_0": "f_0 [%]",
                "v": "v [%]"}
BUDGET_NAMES = {"reference": "reference", "reproducibility": "reproducibility",
                "resolution": "resolution", "interpolation": "interpolation",
                "zero": "zero", "model": "model (held-out)"}
PRINT_CSS = """
@page{size:A4;margin:14mm 12mm}
@media print{body{font-size:9pt;margin:0;padding:0}table{font-size:8pt}
figure img{max-width:170mm}h2{page-break-after:avoid}section.component{page-break-before:always}
section.component:first-of-type{page-break-before:auto}.noprint{display:none}}
.ident td{text-align:left}.ident td:first-child{font-weight:600}.class{font-size:1.2em;font-weight:700}
"""

# the standard's name never wraps inside (a no-break space): the printed titles and the
# terminal's split "ISO" from "376"
ISO = "ISO\u00a0376"


def _fmt(v: float | None, digits: int = 4) -> str:
    return "—" if v is None else f"{v:.{digits}g}"


def _steps(doc: dict, axis: str) -> dict[float, dict]:
    out: dict[float, dict] = {}
    for r in doc["records"]:
        if r["axis"] == axis:
            out.setdefault(r["load"], {})[r["metric"]] = r["value"]
    return dict(sorted(out.items()))


def _unit(doc: dict, axis: str) -> str:
    return doc["units"].get("loads", {}).get(axis, doc["units"]["load"])


def u_figure(doc: dict, axis: str) -> Figure:
    """U (k = 2) against the load of one component's steps."""
    unit = _unit(doc, axis)
    steps = [b for b in doc["budget"] if b["axis"] == axis]
    fig = Figure(figsize=(6.0, 2.6))
    ax = fig.subplots()
    ax.plot([b["load"] for b in steps], [b["U"] for b in steps], "o-", ms=3, color="#1f4e79")
    ax.set_xlabel(f"load {axis} [{unit}]")
    ax.set_ylabel(f"U (k = 2) [{unit}]")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.set_title(f"{axis}: expanded uncertainty of each calibrated step", fontsize=10)
    fig.tight_layout()
    return fig


def certificate_html(doc: dict) -> str:
    """The certificate page: identity, reference, environment, per component the
    figures, class, budget and a plot of U against load; notes and class limits."""
    unit, out_unit = doc["units"]["load"], doc["units"]["output"]
    ref = doc["reference"]
    ident = [("Sensor", doc["sensor"]), ("Serial number", doc["serial"] or "not stated"),
             ("Date", doc["date"]), ("Model file", f"{doc['model']['file']} (fitted "
                                                   f"{doc['model']['created'] or '?'})"),
             ("Calibration data", f"{doc['calibration']['source']}, "
                                  f"{len(doc['calibration']['repetitions'])} repetition(s)"),
             ("Reference", ref["description"] or "not stated"),
             ("Reference uncertainty", f"{ref['uncertainty_percent_k2']:g} % (k = 2)"),
             ("Units", f"loads in {unit}, outputs in {out_unit}")]
    ident += [(f"Environment: {k}", v) for k, v in doc["environment"].items()]
    if not doc["environment"]:
        ident.append(("Environment", "not stated (config: environment)"))
    parts = [f"<h1>Calibration certificate: {escape(doc['sensor'])}</h1>\n",
             table("identity", "Identity", [], [tr(cell(k), cell(str(v))) for k, v in ident])
             .replace("<table ", '<table class="ident" ', 1)]
    cls_rows = [tr(cell(c["axis"]), cell("positive" if c["sign"] == "+" else "negative"),
                   f'<td class="class">{escape(c["class"])}</td>') for c in doc["classes"]]
    parts.append(table("classes", f"Class per component and load sign ({ISO})",
                       [tr(th("component"), th("loads"), th("class"))], cls_rows))
    for n in doc["notes"]:
        parts.append(note(n))
    for axis in doc["full_scale"]:
        unit = _unit(doc, axis)
        steps = _steps(doc, axis)
        metrics = [m for m in METRIC_NAMES if any(m in s for s in steps.values())]
        head = [tr(th(f"load [{unit}]"), *[th(METRIC_NAMES[m]) for m in metrics],
                   th(f"U [{unit}]"))]
        rows = [tr(cell(f"{load:g}"), *[cell(_fmt(s.get(m))) for m in metrics],
                   cell(_fmt(s.get("U")))) for load, s in steps.items()]
        budget = [b for b in doc["budget"] if b["axis"] == axis]
        bhead = [tr(th(f"load [{unit}]"), *[th(BUDGET_NAMES[c]) for c in BUDGET_NAMES],
                    th("w_c"), th("W = 2 w_c"), th(f"U [{unit}]"))]
        brows = [tr(cell(f"{b['load']:g}"), *[cell(_fmt(b[c], 3)) for c in BUDGET_NAMES],
                    cell(_fmt(b["w_c"], 3)), cell(_fmt(b["W"], 3)), cell(_fmt(b["U"], 3)))
                 for b in budget]
        fig = figure_html(f"u-{axis}", to_png(u_figure(doc, axis)), f"U against load, {axis}",
                          f"Expanded uncertainty U (k = 2) of each calibrated {axis} step [{unit}].")
        parts.append(
            f'<section class="component"><h2>Component {escape(axis)} (full scale '
            f"{doc['full_scale'][axis]:g} {escape(unit)})</h2>\n"
            + table(f"figures-{axis}", f"{ISO} figures of {axis} [%], U [{unit}]", head, rows)
            + table(f"budget-{axis}", f"Uncertainty budget of {axis}: relative standard "
                                      "uncertainties [%] (EURAMET cg-4)", bhead, brows)
            + fig + "</section>\n")
    lim = doc["class_limits"]
    lrows = [tr(cell(c), *[cell(f"{v[m]:g}") for m in ("b", "b_prime", "f_c")])
             for c, v in lim["limits_percent"].items()]
    parts.append("<h2>Method</h2>\n" + table(
        "limits", f"Class limits [%] ({lim['source']}), over steps at or above "
                  f"{100 * lim['from_fraction_of_full_scale']:g} % of full scale",
        [tr(th("class"), th("b"), th("b′"), th("|f_c|"))], lrows))
    parts.append(note(
        "b = 100 (max X_i − min X_i)/|mean X_i|; b′ = 100 |X_2 − X_1|/|(X_1 + X_2)/2|; "
        "f_c = 100 (X̄ − X_a)/X_a, X_a a least-squares cubic without constant term per load "
        "sign; X_i the zero-corrected prime output of repetition i. The budget combines "
        "relative standard uncertainties in quadrature (w_c) and states W = 2 w_c, "
        f"U = W |load| in {doc['units']['load']}; the model contribution is the decoupled force's error on "
        "held-out calibration points, interference included."))
    parts.append('<p class="noprint note">Print this page on A4 (the print style sheet '
                 "starts each component on its own page).</p>")
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f"<title>Calibration certificate: {escape(doc['sensor'])}</title>"
            f"<style>{CSS}{PRINT_CSS}</style></head><body>\n{''.join(parts)}</body></html>\n")


def certificate_tables(doc: dict) -> list[Table]:
    """The terminal's view: classes, and per component its figures and U."""
    out = []
    title = f"Certificate of {doc['sensor']}: class ({ISO})"
    t = Table(title=title, min_width=len(title))  # a title as wide as its table never wraps
    for col in ("component", "loads", "class"):
        t.add_column(col)
    for c in doc["classes"]:
        t.add_row(c["axis"], "positive" if c["sign"] == "+" else "negative", c["class"])
    out.append(t)
    for axis in doc["full_scale"]:
        unit = _unit(doc, axis)
        steps = _steps(doc, axis)
        metrics = [m for m in METRIC_NAMES if any(m in s for s in steps.values())]
        t = Table(title=f"{axis}: figures [%] and U (k = 2) [{unit}]")
        for col in (f"load [{unit}]", *[METRIC_NAMES[m] for m in metrics], f"U [{unit}]"):
            t.add_column(col, justify="right")
        for load, s in steps.items():
            t.add_row(f"{load:g}", *[_fmt(s.get(m)) for m in metrics], _fmt(s.get("U")))
        out.append(t)
    return out
