"""The calibration report: one self-contained HTML file a technician can open offline.

:func:`build_report` gathers the evidence for one sensor from a model file, the
optional cross-validation document of ``fsdecouple cv`` (cv.json) and the
optional calibration set: figures as base64 PNG, tables as HTML tables, the
assumption checks as pass/warn badges.  It reads only the keys that cv.json's
layout documents, and every part that needs data which is not there is replaced
by a note that says what to pass.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from html import escape

import numpy as np
import pandas as pd

from .. import __version__
from ..axes import labels_in, load_name
from ..core.metrics import pct
from ..evaluation.checks import assumption_checks
from ..evaluation.cv_results import gamma_index, test_name
from .html import CSS, badge, badge_span, cell, figure_html, note, table, th, tr, worse
from .plots import chi_figure, omega_figure, residual_figure, to_png

METHOD_NAMES = {"initial": "initial (ω⁻¹ only)", "linear": "linear matrix",
                "rbf-mimo": "MIMO RBF NN", "rbf-siso": "SISO RBF NN", "svr": "ε-SVR"}


@dataclass
class Report:
    """A rendered report: the HTML text and each figure as PNG bytes (by file stem)."""

    html: str
    figures: dict[str, bytes] = field(default_factory=dict)



# --- the data behind the figures -------------------------------------------------------

def _point_roles(model, calib, cv) -> tuple[pd.DataFrame, str]:
    pts = calib.points.copy()
    curves = (cv or {}).get("curves")
    if curves:
        train, test = set(curves["train"]), list(curves["test"])
        role = {r: "training" for r in train}
        role.update({r: f"test {test_name(i)}" if i < 2 else "not used" for i, r in enumerate(test)})
        where = (f"marked as in cross-validation round {curves['round']}: trained on "
                 f"repetitions {_reps(train)}, held out {_reps(test)}")
    else:
        used = set((model.report.repetitions if model.report else None) or calib.repetitions)
        role = {r: "training" for r in used}
        where = f"the model was fitted on repetitions {_reps(used)}"
    pts["role"] = [role.get(int(r), "not used") for r in pts["repetition"]]
    return pts, where


def _reps(reps) -> str:
    return ", ".join(str(r) for r in sorted(reps))


def _test_name(cv, rnd: int, test_set: int) -> str:
    """'test I' / 'test II': the held-out repetition's place in its round's fold.

    ``test_set`` is the held-out repetition's number (README, cv.json).
    """
    try:
        return f"test {test_name(cv['folds'][rnd - 1].index(test_set))}"
    except (KeyError, IndexError, ValueError, TypeError):
        return "test"


def _cv_residuals(cv) -> pd.DataFrame | None:
    pts = [p for p in cv.get("points") or [] if p.get("method") == "svr"]
    if not pts:
        return None
    df = pd.DataFrame(pts)
    df["rep"] = df["test_set"]
    df["label"] = [f"rep {t} (round {r}, {_test_name(cv, r, t)})"
                   for r, t in zip(df["round"], df["test_set"], strict=True)]
    df = df.sort_values(["rep", "round"], kind="stable")
    for axis in labels_in(pts):
        applied = np.where(df["axis"] == axis, df["load"], 0.0)
        df[f"e{axis}"] = df[load_name(axis)] - applied
    return df


def _calib_residuals(model, calib) -> pd.DataFrame:
    p, layout = calib.points, model.layout
    f = model.decouple(calib.voltages, rotate=False)
    df = pd.DataFrame({"axis": p["axis"], "label": [f"rep {r} (in-sample)" for r in p["repetition"]]})
    applied = calib.forces
    df["load"] = applied[np.arange(len(p)), [layout.index(a) for a in p["axis"]]]
    for a, axis in enumerate(layout.labels):
        df[f"e{axis}"] = f[:, a] - applied[:, a]
    return df


# --- sections --------------------------------------------------------------------------

def _header(model, cv) -> str:
    units = model.settings.units
    rows = [tr(th("sensor"), cell(model.settings.sensor)),
            tr(th("model fitted"), cell(model.created or "–")),
            tr(th("decouples by"), cell("the coupling error model, eq. (11)" if model.method == "svr"
                                        else "the least-squares calibration matrix (fit --method "
                                             f"{(model.report.verdict or {}).get('asked', 'linear')})")),
            tr(th("units"), cell(f"loads in {units.load}, outputs in {units.output}")),
            tr(th("repetitions in the model"), cell(_reps(model.report.repetitions if model.report else []))),
            tr(th("report written by"), cell(f"fsdecouple {__version__}"))]
    if cv:
        rows.append(tr(th("cross-validation"), cell(f"{cv.get('created', '?')}, fsdecouple "
                                                     f"{cv.get('fsdecouple_version', '?')}")))
    checks = assumption_checks(model)
    warns = [f"{c.name} {c.subject}" for c in checks if c.status != "pass"]
    summary = f" {len(checks) - len(warns)} pass, {len(warns)} warn"
    if warns:
        summary += f" ({', '.join(warns)})"
    status = badge_span("warn" if warns else "pass")
    rows.append(tr(th("assumption checks"), f"<td>{status}{escape(summary)}</td>"))
    g = gamma_index((cv or {}).get("records"))
    svr = [v for (_, _, m, _), v in g.items() if m == "svr"]
    if svr:
        rows.append(tr(th("worst held-out γ, ε-SVR"), cell(pct(max(svr)))))
    return table("table-summary", "Sensor and report", [], rows)


def _provenance(model, cv, calib) -> str:
    out = ""
    files = [("model", f["path"], f["sha256"]) for f in model.provenance.get("files", [])]
    if cv:
        files += [("cv", f["path"], f["sha256"]) for f in cv.get("calibration", {}).get("files", [])]
    if calib is not None:
        files += [("plotted", p, h) for p, h in calib.files]
    out += table("table-provenance", "Data provenance: files and their SHA-256",
                 [tr(th("used by"), th("file"), th("sha256"))],
                 [tr(cell(u), cell(p), f'<td class="mono">{escape(h)}</td>') for u, p, h in files])
    model_digests = {f["sha256"] for f in model.provenance.get("files", [])}
    if calib is not None and {h for _, h in calib.files} != model_digests:
        out += note("The calibration files plotted here are not exactly the files the model "
                    "was fitted on (digests differ): the points may not match the curves.")
    libs = model.provenance.get("libraries", {})
    if libs:
        out += note("Libraries at fit time: " + ", ".join(f"{k} {v}" for k, v in sorted(libs.items())))
    rows = []
    for key, value in sorted(model.settings.to_dict().items()):
        if isinstance(value, dict):
            text = ", ".join(f"{k}={json.dumps(v)}" for k, v in sorted(_flatten(value).items()))
        else:
            text = json.dumps(value)
        rows.append(tr(cell(key), f'<td class="mono">{escape(text)}</td>'))
    out += table("table-settings", "Settings the model was fitted with",
                 [tr(th("setting"), th("value"))], rows)
    return out


def _flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flatten(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def _model_tables(model) -> str:
    rep = model.report.to_dict() if model.report else {}
    rows = [tr(cell(a), cell(f"{model.k[i]:.6g}"), cell(f"{1 / model.k[i]:.4f}"),
               cell(f"{rep.get('r2', {}).get(a, float('nan')):.6f}"),
               cell(str(rep.get("n_points", {}).get(a, "–"))))
            for i, a in enumerate(model.layout.labels)]
    out = table("table-omega", "Non-coupling functions ω (eq. 2) of the model file",
                [tr(th("axis"), th("k [V/N]"), th("1/k [N/V] (eq. 13)"), th("R²"), th("points"))], rows)
    rows = []
    for name, c in model.chi.items():
        rows.append(tr(cell(f"χ{name}"), cell(model.layout.outputs[c.input_axis]),
                       cell(f"{c.support_vectors.size} / {c.n_points}"),
                       cell(f"{c.input_range[0]:+.4f} … {c.input_range[1]:+.4f}")))
    out += table("table-chi", "Corrected coupling functions χ (eq. 4): ε-SVRs",
                 [tr(th("χ"), th("input"), th("support vectors / points"), th("input range [V]"))], rows)
    rows = []
    for a in model.layout.labels:
        b, g = rep.get("gamma_before", {}).get(a), rep.get("gamma_after", {}).get(a)
        rows.append(tr(cell(a), cell(pct(b)), cell(pct(g), worse(g, b))))
    out += table("table-gamma-fit", "Interference error γ (eq. 12) on the calibration data "
                 "(in-sample, all repetitions pooled), % F.S.",
                 [tr(th("loaded axis"), th("initial (ω⁻¹ only)"), th("after decoupling (eq. 11)"))], rows)
    return out


def _gamma_tables(cv) -> str:
    g = gamma_index(cv.get("records"))
    labels = labels_in(cv.get("records"))  # the components scored
    keys = sorted({(r, t) for r, t, _, _ in g})
    methods = [m for m in cv.get("methods", []) if any(k[2] == m for k in g)]

    levels = cv.get("protocol") == "levels"

    def held(r, t):
        return f"level {t} (interior points)" if levels else f"{_test_name(cv, r, t)} (rep {t})"

    def val(r, t, m, a, base="initial"):
        v, b = g.get((r, t, m, a)), g.get((r, t, base, a))
        return cell(pct(v), m != base and worse(v, b))

    head = [tr(th("round", rowspan=2), th("held out", rowspan=2),
               *(th(f"γ{a}", span=len(methods)) for a in labels)),
            tr(*(th(METHOD_NAMES.get(m, m)) for _ in labels for m in methods))]
    rows = [tr(cell(str(r)), cell(held(r, t)), *(val(r, t, m, a) for a in labels for m in methods))
            for r, t in keys]
    out = table("table-gamma-methods", "Table 1 analogue: interference error γ (eq. 12) of the "
                f"held-out {'load levels' if levels else 'repetitions'} ({cv.get('protocol', 'repetitions')} "
                "protocol), every method, % F.S.", head, rows)
    absent = [METHOD_NAMES[m] for m in METHOD_NAMES if m not in methods]
    if absent:
        out += note("Not in cv.json (not run): " + ", ".join(absent) + ".")
    if "svr" in methods:
        rows = [tr(cell(str(r)), cell(held(r, t)), *(val(r, t, "svr", a) for a in labels)) for r, t in keys]
        worst = [max((g.get((r, t, "svr", a)) or 0.0) for r, t in keys) for a in labels]
        rows.append(tr(th("worst"), cell(""), *(cell(pct(w)) for w in worst)))
        out += table("table-gamma-svr", "Table 3 analogue: γ after decoupling by the coupling "
                     "error model and ε-SVRs, % F.S.",
                     [tr(th("round"), th("held out"), *(th(f"γ{a}") for a in labels))], rows)
    return out


def _gross_tables(cv) -> str:
    ge = cv.get("gross_error")
    if not ge:
        return note("No gross-error run in cv.json (fsdecouple cv --gross-error AXIS:REP:POINT:OFFSET "
                    "adds Table 5).")
    spec = ge.get("spec", {})
    clean, gross = gamma_index(cv.get("records")), gamma_index(ge.get("records"))
    labels = labels_in(cv.get("records"))  # the components scored
    keys = sorted({(r, t) for r, t, m, _ in gross if m == "svr"})
    rows = []
    for r, t in keys:
        cells = []
        for a in labels:
            c, w = clean.get((r, t, "svr", a)), gross.get((r, t, "svr", a))
            cells += [cell(pct(c)), cell(pct(w), worse(w, gross.get((r, t, "initial", a))))]
        rows.append(tr(cell(str(r)), cell(f"{_test_name(cv, r, t)} (rep {t})"), *cells))
    head = [tr(th("round", rowspan=2), th("held out", rowspan=2),
               *(th(f"γ{a} (ε-SVR)", span=2) for a in labels)),
            tr(*(th(x) for _ in labels for x in ("without", "with gross error")))]
    out = note(f"Gross error: prime voltage of point {spec.get('point')} of the {spec.get('axis')} sweep "
               f"of repetition {spec.get('repetition')} moved by {spec.get('offset')} V (Section 4.4).")
    out += table("table-gross-error", "Table 5 analogue: γ with and without the gross error, % F.S.",
                 head, rows)
    rows = []
    for o in ge.get("omega", []):
        change = o["inverse_gross"] / o["inverse_clean"] - 1.0
        rows.append(tr(cell(str(o["round"])), cell(o["axis"]), cell(f"{o['k_clean']:.6g}"),
                       cell(f"{o['k_gross']:.6g}"), cell(f"{o['inverse_clean']:.3f}"),
                       cell(f"{o['inverse_gross']:.3f}"), cell(f"{100 * change:+.2f} %")))
    out += table("table-omega-gross", "ω with and without the gross error (eq. 13 vs eq. 14)",
                 [tr(*(th(h) for h in ("round", "axis", "k clean [V/N]", "k gross [V/N]",
                                       "1/k clean [N/V] (eq. 13)", "1/k gross [N/V] (eq. 14)",
                                       "change of 1/k")))], rows)
    return out


def _task_table(cv) -> str:
    task = cv.get("task")
    if not task:
        return note("No combined-load validation in cv.json (fsdecouple cv --task VOLTAGES "
                    "--task-forces FORCES adds it).")
    v = {(r["round"], r["method"], r["axis"], r["metric"]): r["value"] for r in task.get("records", [])}
    rounds = sorted({k[0] for k in v})
    labels = labels_in(task.get("records"))  # the components scored
    methods = [m for m in cv.get("methods", []) if any(k[1] == m for k in v)]
    rows = []
    for r in rounds:
        for m in methods:
            cells = []
            for a in labels:
                for metric in ("max_error", "rms_error"):
                    x, b = v.get((r, m, a, metric)), v.get((r, "initial", a, metric))
                    cells.append(cell(pct(x, 3), m != "initial" and worse(x, b)))
            rows.append(tr(cell(str(r)), cell(METHOD_NAMES.get(m, m)), *cells))
    head = [tr(th("round", rowspan=2), th("method", rowspan=2),
               *(th(load_name(a), span=2) for a in labels)),
            tr(*(th(x) for _ in labels for x in ("max error", "rms error")))]
    out = note(f"Combined loads: {task.get('voltages')} against {task.get('forces')}, "
               f"{task.get('rows')} rows, tare {task.get('tare')}.")
    return out + table("table-task", "Combined-load comparison: error as % of each axis's full scale",
                       head, rows)


def _fmt_check(c: dict) -> tuple[str, str]:
    if c["name"] == "linearity":
        return f"{c['value']:.6f}", f"≥ {c['limit']:g}"
    if c["name"] == "slope":
        return f"{c['value']:.4f}", f"≤ {c['limit']:g}"
    return pct(c["value"], 3), f"≤ {pct(c['limit'], 2)}"


CHECK_NAMES = {"linearity": "linearity of ω, R² (assumption 1)",
               "coupling": "coupling error / F.S. output",
               "slope": "max |dχ/du|",
               "second_order": "second-order bound, eq. (6)"}


def _checks(model, cv) -> str:
    rows = []
    order = list(CHECK_NAMES)
    checks = sorted((c.to_dict() for c in assumption_checks(model)),
                    key=lambda c: (order.index(c["name"]) if c["name"] in order else len(order)))
    for c in checks:
        value, limit = _fmt_check(c)
        rows.append(tr(cell(CHECK_NAMES.get(c["name"], c["name"])), cell(c["subject"]),
                       cell(value), cell(limit), badge(c["status"])))
    out = table("table-checks", "Assumption checks of Section 2.1 on the model file",
                [tr(th("check"), th("subject"), th("value"), th("limit"), th("status"))], rows)
    checks = (cv or {}).get("checks") or []
    if checks:
        rows = []
        for r in sorted({c.get("round") for c in checks}):
            cs = [c for c in checks if c.get("round") == r]
            warns = [f"{c['name']} {c['subject']}" for c in cs if c["status"] != "pass"]
            rows.append(tr(cell(str(r)), cell(str(len(cs) - len(warns))), cell(str(len(warns))),
                           badge("warn" if warns else "pass"), cell(", ".join(warns) or "–")))
        out += table("table-cv-checks", "The same checks on each cross-validation round's model",
                     [tr(th("round"), th("pass"), th("warn"), th("status"), th("warnings"))], rows)
    return out




def build_report(model, cv: dict | None = None, calib=None) -> Report:
    """Render the calibration report of ``model``.

    Parameters
    ----------
    model : CouplingErrorModel
    cv : dict, optional
        A cv.json document (:func:`load_cv_results`).
    calib : CalibrationSet, optional
        The calibration set, to plot its points.
    """
    figs: dict[str, bytes] = {}
    body = [f"<h1>Calibration report: {escape(model.settings.sensor)}</h1>\n",
            _header(model, cv),
            '<p id="certificate-link">Calibration certificate (ISO 376 figures, class, uncertainty '
            'budget): <a href="certificate.html">certificate.html</a>, written beside this report '
            "by <code>fsdecouple certificate MODEL CALIB -o certificate.html</code>.</p>\n"]
    if model.warnings:
        body.append("<ul>" + "".join(f"<li>warning: {escape(w)}</li>" for w in model.warnings) + "</ul>\n")

    points, where = _point_roles(model, calib, cv) if calib is not None else (None, "")
    body.append("<h2>Non-coupling functions ω (Figure 6)</h2>\n")
    figs["figure6_omega"] = to_png(omega_figure(model, points))
    body.append(figure_html(
        "fig-omega", figs["figure6_omega"], "Figure 6: prime voltage against prime force per axis",
        "Per axis: prime voltage against prime force of that axis's sweeps and the fitted line of "
        "the model file (eq. 2); slope k, 1/k (eq. 13) and R². "
        + (f"Points {where}; lower row: deviation from the line [mV]." if calib is not None
           else "No calibration points: pass --calib CALIB to plot them.")))
    body.append(_model_tables(model))

    body.append("<h2>Corrected coupling functions χ (Figure 7)</h2>\n")
    curves = (cv or {}).get("curves") or {}
    chi_curves = curves.get("chi")
    figs["figure7_chi"] = to_png(chi_figure(model, points, chi_curves))
    if chi_curves:
        src = (f"ε-SVR curves (solid) of cross-validation round {curves.get('round')}"
               + (", SISO RBF NN curves dashed" if any(c.get("rbf-siso") for c in chi_curves.values())
                  else "; no SISO RBF NN curves in cv.json (not run), so no dashed curve"))
    else:
        src = "ε-SVR curves (solid) of the model file"
    body.append(figure_html(
        "fig-chi", figs["figure7_chi"], "Figure 7: the "
        f"{'six' if len(model.chi) == 6 else len(model.chi)} corrected coupling functions",
        f"Each χab: coupling error eab on channel a [mV] against the prime voltage ub [V]. {src}. "
        + (f"Points {where}." if calib is not None else "No calibration points: pass --calib CALIB "
           "to plot the training and held-out points.")))

    body.append("<h2>Interference error γ (Tables 1, 3 and 5)</h2>\n")
    if cv:
        body.append(note("Cells marked ▲ (bold, boxed) are worse than the initial data of the same "
                         "held-out repetition."))
        body.append(_gamma_tables(cv))
        body.append(_gross_tables(cv))
        body.append("<h2>Combined loads</h2>\n")
        body.append(_task_table(cv))
    else:
        body.append(note("No cross-validation results: run fsdecouple cv CALIB -o cv.json and pass "
                         "--cv cv.json to add Tables 1, 3 and 5 and the combined-load comparison."))

    body.append("<h2>Assumption checks</h2>\n")
    body.append(_checks(model, cv))

    body.append("<h2>Residuals</h2>\n")
    residuals = _cv_residuals(cv) if cv else None
    if residuals is not None:
        title = "Decoupled force error of each held-out repetition (ε-SVR, cross-validation)"
        cap = ("Decoupled minus applied force [N] against the applied load, per loaded axis (rows) "
               "and force component (columns); one series per held-out repetition, each decoupled "
               "by the model of the round that held it out.")
    elif calib is not None:
        residuals = _calib_residuals(model, calib)
        title = "Decoupled force error on the calibration data (in-sample, not held out)"
        cap = ("Decoupled minus applied force [N] against the applied load, per loaded axis (rows) "
               "and force component (columns), one series per repetition. These points trained the "
               "model: pass --cv cv.json for held-out residuals.")
    if residuals is not None:
        figs["residuals"] = to_png(residual_figure(residuals, title, model.settings.load_unit))
        body.append(figure_html("fig-residuals", figs["residuals"], "Residual plot", cap))
    else:
        body.append(note("No residual plot: pass --cv cv.json or --calib CALIB."))

    body.append("<h2>Provenance and settings</h2>\n")
    body.append(_provenance(model, cv, calib))

    html = ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            f"<title>fsdecouple calibration report: {escape(model.settings.sensor)}</title>\n"
            f"<style>{CSS}</style>\n</head>\n<body>\n" + "".join(body) + "</body>\n</html>\n")
    return Report(html, figs)
