"""The certificate a lab signs: one self-contained HTML page that prints on A4, the
PDF (:mod:`.certificate_pdf`) and the terminal's tables, all from the
``fsdecouple.certificate`` document
(:func:`fsdecouple.evaluation.certificate_doc.certificate`).

:func:`certificate_blocks` lays the certificate out once, as a list of headings,
tables, notes and figures; the HTML and the PDF each render that list, so both
carry the same content and the same figures.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from matplotlib.figure import Figure
from rich.table import Table

from .html import CSS, cell, escape, figure_html, note, table, th, tr
from .plots import to_png
from .words import counted

METRIC_NAMES = {"b": "b [%]", "b_prime": "b′ [%]", "f_c": "f_c [%]", "f_0": "f_0 [%]",
                "v": "v [%]", "c": "c [%]"}
BUDGET_NAMES = {"reference": "reference", "reproducibility": "reproducibility",
                "repeatability": "repeatability", "resolution": "resolution",
                "reversibility": "reversibility", "interpolation": "interpolation",
                "zero": "zero", "temperature": "temperature", "drift": "drift",
                "model": "model (fsdecouple)"}
CRITERIA = {"b": "b (reproducibility)", "b_prime": "b′ (repeatability)",
            "f_c": "f_c (interpolation)", "f_0": "f_0 (zero)", "v": "v (reversibility)",
            "c": "c (creep)", "reference": "reference uncertainty (Table 3)",
            "resolution": "resolution (no step in the class range)",
            "repetitions": "no b or b′ at a step (too few repetitions reach it)"}
PRINT_CSS = """
@page{size:A4;margin:14mm 12mm}
@media print{body{font-size:9pt;margin:0;padding:0}table{font-size:8pt}
figure img{max-width:170mm}h2{page-break-after:avoid}section.component{page-break-before:always}
section.component:first-of-type{page-break-before:auto}.noprint{display:none}}
.ident td{text-align:left}.ident td:first-child{font-weight:600}.class{font-size:1.2em;font-weight:700}
table[id^="budget-"]{font-size:.8em}table[id^="budget-"] th,table[id^="budget-"] td{padding:.2em .35em}
table[id^="budget-"] th{white-space:normal}
"""

# the standard's name never wraps inside (a no-break space): the printed titles and the
# terminal's split "ISO" from "376"
ISO = "ISO\u00a0376"


@dataclass
class Block:
    """One piece of the certificate: ``kind`` is ``title``, ``heading`` (a component's
    section starts), ``table``, ``note`` or ``figure`` (a component's U against load)."""

    kind: str
    text: str = ""
    ident: str = ""
    head: list[str] = field(default_factory=list)
    rows: list[list[str]] = field(default_factory=list)
    emphasis: int | None = None  # a table column shown larger (the class)


def fmt(v: float | None, digits: int = 4) -> str:
    """A figure as the certificate shows it (the same text in HTML, PDF and terminal)."""
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


def _limited(c: dict) -> str:
    why = c.get("limited_by") or []
    return ", ".join(CRITERIA.get(w, w) for w in why) if why else "— (the best class)"


def _drift_row(doc: dict) -> str:
    """The budget's drift term's basis, as the certificate states it: per component where
    the components' sources differ."""
    d = doc["drift"]
    if d["source"] is None:
        return "not stated (no compare document, no config drift): 0"
    models = d.get("models") or []

    def said(source: str | None) -> str:
        if source is None:
            return "none stated: 0"
        if source == "config drift":
            return f"{d.get('percent'):g} % of each step (config drift)"
        return source + (f": {' against '.join(models)}" if models else "")

    by = d["components"]
    if len(set(by.values())) > 1:
        return "; ".join(f"{axis}: {said(source)}" for axis, source in by.items())
    return said(next(iter(by.values())))


def certificate_blocks(doc: dict) -> list[Block]:
    """The certificate's content in order: identity, classes, notes, per component its
    figures, budget and plot, then the method (class limits and budget sources)."""
    unit, out_unit = doc["units"]["load"], doc["units"]["output"]
    ref = doc["reference"]
    ident = [("Sensor", doc["sensor"]), ("Serial number", doc["serial"] or "not stated"),
             ("Date of issue", doc["date"]), ("Model file", f"{doc['model']['file']} (fitted "
                                                   f"{doc['model']['created'] or '?'})"),
             ("Calibration data", f"{doc['calibration']['source']}, "
                                  f"{counted(len(doc['calibration']['repetitions']), 'repetition')}"),
             ("Reference", ref["description"] or "not stated"),
             ("Reference uncertainty", f"{ref['uncertainty_percent_k2']:g} % (k = 2)"),
             ("Units", f"loads in {unit}, outputs in {out_unit}"),
             ("Drift between calibrations", _drift_row(doc))]
    ident += [(f"Environment: {k}", str(v)) for k, v in doc["environment"].items()]
    if not doc["environment"]:
        ident.append(("Environment", "not stated (config: environment)"))
    out = [Block("title", f"Calibration certificate: {doc['sensor']}"),
           Block("table", "Identity", "identity", [], [[k, str(v)] for k, v in ident])]
    out.append(Block("table", f"Class per component and load sign ({ISO}:2011)", "classes",
                     ["component", "loads", "class", "limited by", f"class range from [{unit}]"],
                     [[c["axis"], "positive" if c["sign"] == "+" else "negative", c["class"],
                       _limited(c), f"{c['from']:.4g}" if "from" in c and c["class"] != "none"
                       else "—"]
                      for c in doc["classes"]], emphasis=2))
    out += [Block("note", n) for n in doc["notes"]]
    for axis in doc["full_scale"]:
        unit = _unit(doc, axis)
        steps = _steps(doc, axis)
        metrics = [m for m in METRIC_NAMES if any(m in s for s in steps.values())]
        out.append(Block("heading", f"Component {axis} (full scale {doc['full_scale'][axis]:g} "
                                    f"{unit})", axis))
        out.append(Block("table", f"{ISO} figures of {axis} [%], U [{unit}]", f"figures-{axis}",
                         [f"load [{unit}]", *[METRIC_NAMES[m] for m in metrics], f"U [{unit}]"],
                         [[f"{load:g}", *[fmt(s.get(m)) for m in metrics], fmt(s.get("U"))]
                          for load, s in steps.items()]))
        budget = [b for b in doc["budget"] if b["axis"] == axis]
        names = [c for c in BUDGET_NAMES if budget and c in budget[0]]
        out.append(Block("table", f"Uncertainty budget of {axis}: relative standard "
                                  "uncertainties [%] (EURAMET cg-4 v3.0)", f"budget-{axis}",
                         [f"load [{unit}]", *[BUDGET_NAMES[c] for c in names], "w_c",
                          "W = 2 w_c", f"U [{unit}]"],
                         [[f"{b['load']:g}", *[fmt(b[c], 3) for c in names], fmt(b["w_c"], 3),
                           fmt(b["W"], 3), fmt(b["U"], 3)] for b in budget]))
        out.append(Block("figure", f"Expanded uncertainty U (k = 2) of each calibrated {axis} "
                                   f"step [{unit}].", axis))
    lim = doc["class_limits"]
    cols = ("b", "b_prime", "f_c", "f_0", "v", "c")
    ref_lim = lim.get("reference_limits_percent_k2", {})
    res = lim.get("lower_limit_resolutions", {})
    out.append(Block("heading", "Method", "method"))
    out.append(Block("table", f"Class limits [%] ({lim['source']}; reference forces: "
                              f"{lim.get('reference_source', 'ISO 376:2011, Table 3')})", "limits",
                     ["class", "b", "b′", "|f_c|", "|f_0|", "v", "c", "reference (k = 2)",
                      "range from"],
                     [[c, *[f"{v[m]:g}" if m in v else "—" for m in cols],
                       f"{ref_lim[c]:g}" if c in ref_lim else "—",
                       f"{res[c]:g} r" if c in res else "—"]
                      for c, v in lim["limits_percent"].items()]))
    temperature = _temperature_block(doc)
    if temperature is not None:
        out.append(temperature)
    sources = doc.get("budget_sources", {})
    out.append(Block("table", "Sources of the budget's contributions", "sources",
                     ["contribution", "source"],
                     [[BUDGET_NAMES.get(c, c), s] for c, s in sources.items()]))
    out.append(Block("note", (
        "b = 100 (max X_i − min X_i)/|mean X_i|; b′ = 100 |X_2 − X_1|/|(X_1 + X_2)/2|; "
        "f_c = 100 (X̄ − X_a)/X_a, X_a a least-squares cubic without constant term per load "
        "sign; f_0 = 100 (i_f − i_0)/X_N; v = 100 |X′ − X|/X; c = 100 (i_300 − i_30)/X_N; "
        "X_i the deflection of repetition i. A class holds when every criterion the sweeps "
        "give is within its limits at every step of its range (from the resolution's lower "
        f"limit; {100 * lim['from_fraction_of_full_scale']:g} % of full scale where the "
        "resolution is unknown), and the reference uncertainty within Table 3's. The budget "
        "combines relative standard uncertainties in quadrature (w_c) and states W = 2 w_c, "
        f"U = W |load| in {doc['units']['load']}; the model contribution is fsdecouple's own "
        "addition: the decoupled force's error on held-out calibration points, interference "
        "included.")))
    return out


def certificate_html(doc: dict) -> str:
    """The certificate page: :func:`certificate_blocks` as one self-contained HTML page."""
    parts, open_section = [], False
    for b in certificate_blocks(doc):
        if b.kind == "title":
            parts.append(f"<h1>{escape(b.text, keep='')}</h1>\n")
        elif b.kind == "heading":
            if open_section:
                parts.append("</section>\n")
            open_section = b.ident != "method"
            parts.append(f'<section class="component"><h2>{escape(b.text)}</h2>\n'
                         if open_section else f"<h2>{escape(b.text)}</h2>\n")
        elif b.kind == "note":
            parts.append(note(b.text))
        elif b.kind == "figure":
            axis = b.ident
            parts.append(figure_html(f"u-{axis}", to_png(u_figure(doc, axis)),
                                     f"U against load, {axis}", b.text))
        else:
            head = [tr(*[th(h) for h in b.head])] if b.head else []
            rows = [tr(*[f'<td class="class">{escape(v)}</td>' if i == b.emphasis else cell(v)
                         for i, v in enumerate(r)]) for r in b.rows]
            html = table(b.ident, b.text, head, rows)
            parts.append(html.replace("<table ", '<table class="ident" ', 1)
                         if b.ident == "identity" else html)
    if open_section:
        parts.append("</section>\n")
    parts.append('<p class="noprint note">Print this page on A4 (the print style sheet '
                 "starts each component on its own page), or write the PDF: "
                 "certificate -o certificate.pdf.</p>")
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f"<title>Calibration certificate: {escape(doc['sensor'], keep='')}</title>"
            f"<style>{CSS}{PRINT_CSS}</style></head><body>\n{''.join(parts)}</body></html>\n")


TEMPERATURE_FORM = "u = (1 + g (T - T0)) u(T0) + b (T - T0)"  # core/temperature.py


def _temperature_where(t: dict) -> str:
    span = f", calibrated {t['span'][0]:.4g} .. {t['span'][1]:.4g} {t['unit']}" if "span" in t else ""
    return f"T0 = {t['t0']:g} {t['unit']}{span}"


def _temperature_block(doc: dict) -> Block | None:
    """The temperature terms the outputs were corrected by (issue 31), if the model has them."""
    t = doc.get("temperature")
    if t is None:
        return None
    return Block("table", f"Temperature terms: {TEMPERATURE_FORM}, {_temperature_where(t)}",
                 "temperature",
                 ["output", f"b [{doc['units'].get('output', 'V')}/K]", "g [ppm/K]"],
                 [[o, f"{t['b'][o]:+.4g}", f"{1e6 * t['g'][o]:+.1f}"] for o in t["b"]])


def certificate_tables(doc: dict) -> list[Table]:
    """The terminal's view: classes and what limits them, per component its figures and U, and
    the temperature terms where the model has them."""
    out = []
    title = f"Certificate of {doc['sensor']}: class ({ISO})"
    t = Table(title=title, min_width=len(title))  # a title as wide as its table never wraps
    for col in ("component", "loads", "class", "limited by"):
        t.add_column(col)
    for c in doc["classes"]:
        t.add_row(c["axis"], "positive" if c["sign"] == "+" else "negative", c["class"],
                  _limited(c))
    out.append(t)
    for axis in doc["full_scale"]:
        unit = _unit(doc, axis)
        steps = _steps(doc, axis)
        metrics = [m for m in METRIC_NAMES if any(m in s for s in steps.values())]
        t = Table(title=f"{axis}: figures [%] and U (k = 2) [{unit}]")
        for col in (f"load [{unit}]", *[METRIC_NAMES[m] for m in metrics], f"U [{unit}]"):
            t.add_column(col, justify="right")
        for load, s in steps.items():
            t.add_row(f"{load:g}", *[fmt(s.get(m)) for m in metrics], fmt(s.get("U")))
        out.append(t)
    temperature = _temperature_block(doc)
    if temperature is not None:  # the certificate's own table, on the terminal too
        title = f"Temperature terms ({_temperature_where(doc['temperature'])})"
        t = Table(title=title, caption=TEMPERATURE_FORM, min_width=min(len(title), 78))
        for i, col in enumerate(temperature.head):
            t.add_column(col, justify="left" if i == 0 else "right")
        for row in temperature.rows:
            t.add_row(*row)
        out.append(t)
    return out

