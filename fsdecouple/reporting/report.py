"""The calibration report: one self-contained HTML file a technician can open offline.

:func:`build_report` gathers the evidence for one sensor from a model file, the
optional cross-validation document of ``fsdecouple cv`` (cv.json) and the
optional calibration set: figures as base64 PNG, tables as HTML tables, the
assumption checks as pass/warn badges.  It reads only the keys that cv.json's
layout documents, and every part that needs data which is not there is replaced
by a note that says what to pass.
"""

from __future__ import annotations

import html
import json
from dataclasses import dataclass, field
from urllib.parse import quote

import numpy as np
import pandas as pd

from .. import __version__
from ..axes import labels_in, load_name
from ..core.metrics import pct
from ..errors import InputError, printable
from ..evaluation.checks import assumption_checks
from ..evaluation.cv_results import gamma_index, test_name
from ..units import output_display
from .cv_tables import cv_test_name, gamma_tables, gross_tables, task_table
from .html import CSS, badge, badge_span, cell, escape, figure_html, note, table, th, tr, worse
from .plots import chi_figure, omega_figure, residual_figure, to_png
from .temperature_tables import temperature_html
from .words import plural, unit_words


@dataclass
class Report:
    """A rendered report: the HTML text and each figure as PNG bytes (by file stem)."""

    html: str
    figures: dict[str, bytes] = field(default_factory=dict)



# --- the data behind the figures -------------------------------------------------------

def _point_roles(model, calib, cv) -> tuple[pd.DataFrame, str]:
    pts = calib.points.copy()
    curves = (cv or {}).get("curves")
    if curves and _levels(cv):
        held = ((cv.get("folds") or [[]])[curves["round"] - 1:curves["round"]] or [[]])[0]
        role = {r: "training" for r in calib.repetitions}
        where = (f"of every repetition, as in cross-validation round {curves['round']}, which held "
                 f"out load level {_reps(held) or '?'} of each sweep (the load levels protocol)")
    elif curves:
        train, test = set(curves["train"]), list(curves["test"])
        role = {r: "training" for r in train}
        role.update({r: f"test {test_name(i)}" if i < 2 else "not used" for i, r in enumerate(test)})
        where = (f"marked as in cross-validation round {curves['round']}: trained on "
                 f"{_reps(train, 'repetition')}, held out {_reps(test)}")
    else:
        used = set((model.report.repetitions if model.report else None) or calib.repetitions)
        role = {r: "training" for r in used}
        where = f"the model was fitted on {_reps(used, 'repetition')}"
    pts["role"] = [role.get(int(r), "not used") for r in pts["repetition"]]
    return pts, where


def _reps(reps, noun: str = "") -> str:
    """``1, 2, 3``; with ``noun``: ``repetitions 1, 2, 3`` or ``repetition 1``."""
    listed = ", ".join(str(r) for r in sorted(reps))
    return f"{plural(len(reps), noun)} {listed}" if noun else listed


def _shown(units) -> dict[str, str]:
    """The data's own units for captions: loads, outputs, and small output figures.  Where
    components differ (N and N·m), the config already made ``load`` read "N / N·m"."""
    small = units.output if units.outputs else output_display(units.output)[1]
    return {"load": units.load, "output": units.output, "small": small}


def _levels(cv) -> bool:
    return (cv or {}).get("protocol") == "levels"


def _cv_residuals(cv) -> pd.DataFrame | None:
    pts = [p for p in cv.get("points") or [] if p.get("method") == "svr"]
    if not pts:
        return None
    df = pd.DataFrame(pts)
    df["rep"] = df["test_set"]
    df["label"] = [f"level {t} (round {r})" if _levels(cv)
                   else f"rep {t} (round {r}, {cv_test_name(cv, r, t)})"
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
    end = [v for (_, _, m, _), v in gamma_index((cv or {}).get("end_records")).items() if m == "svr"]
    if end and _levels(cv):
        rows.append(tr(th("worst held-out γ on end points (extrapolation), ε-SVR"),
                       cell(pct(max(end)))))
    return table("table-summary", "Sensor and report", [], rows)


def plots_other_files(model, calib) -> bool:
    """The calibration set given to plot is not, by content, the set the model was fitted on."""
    return {h for _, h in calib.files} != {f["sha256"] for f in model.provenance.get("files", [])}


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
    if calib is not None and plots_other_files(model, calib):
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
    units = model.settings.units
    same = not (units.loads or units.outputs)  # one unit each: in the headers, not per cell

    def with_unit(x: float, unit: str) -> str:  # six significant digits; the unit per cell if mixed
        return f"{x:.6g}" if same else f"{x:.6g} {unit}"

    rows = [tr(cell(a), cell(with_unit(model.k[i], f"{units.output_of(i)}/{units.load_of(i)}")),
               cell(with_unit(1 / model.k[i], f"{units.load_of(i)}/{units.output_of(i)}")),
               cell(f"{rep.get('r2', {}).get(a, float('nan')):.6f}"),
               cell(str(rep.get("n_points", {}).get(a, "–"))))
            for i, a in enumerate(model.layout.labels)]
    k_unit = f" [{units.output}/{units.load}]" if same else ""
    inv_unit = f" [{units.load}/{units.output}]" if same else ""
    out = table("table-omega", "Non-coupling functions ω (eq. 2) of the model file",
                [tr(th("axis"), th(f"k{k_unit}"), th(f"1/k{inv_unit} (eq. 13)"), th("R²"),
                    th("points"))], rows)
    rows = []
    for name, c in model.chi.items():
        b = units.output_of(c.input_axis)
        span = f"{c.input_range[0]:+.6g} … {c.input_range[1]:+.6g}"
        rows.append(tr(cell(f"χ{name}"), cell(model.layout.outputs[c.input_axis]),
                       cell(f"{c.support_vectors.size} / {c.n_points}"),
                       cell(span if same else f"{span} {b}")))
    range_unit = f" [{units.output}]" if same else ""
    out += table("table-chi", "Corrected coupling functions χ (eq. 4): ε-SVRs",
                 [tr(th("χ"), th("input"), th("support vectors / points"),
                     th(f"input range{range_unit}"))], rows)
    rows = []
    for a in model.layout.labels:
        b, g = rep.get("gamma_before", {}).get(a), rep.get("gamma_after", {}).get(a)
        rows.append(tr(cell(a), cell(pct(b)), cell(pct(g), worse(g, b))))
    out += table("table-gamma-fit", "Interference error γ (eq. 12) on the calibration data "
                 "(in-sample, all repetitions pooled), % F.S.",
                 [tr(th("loaded axis"), th("initial (ω⁻¹ only)"), th("after decoupling (eq. 11)"))], rows)
    return out


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
            folds = cv.get("folds") or []
            # the levels protocol's last round holds out the end levels (cv.json end_records)
            end = _levels(cv) and isinstance(r, int) and 0 < r <= len(folds) and not folds[r - 1]
            rows.append(tr(cell(f"{r} (end levels)" if end else str(r)), cell(str(len(cs) - len(warns))),
                           cell(str(len(warns))),
                           badge("warn" if warns else "pass"), cell(", ".join(warns) or "–")))
        out += table("table-cv-checks", "The same checks on each cross-validation round's model",
                     [tr(th("round"), th("pass"), th("warn"), th("status"), th("warnings"))], rows)
    return out


def _unit_words(units) -> str:
    """``{load: gf, output: count}`` (a settings document's units; None: the paper's) as words."""
    units = units if isinstance(units, dict) else {"load": "N", "output": "V"}
    return (f"{printable(unit_words(units.get('load')))} and "
            f"{printable(unit_words(units.get('output')))}")


def check_cv_fits(model, cv: dict, source: str = "cv.json") -> None:
    """A cv.json of another sensor (a six-axis cv for a 3-axis model, a gram-force and count
    cv for a model in N and V) is refused: its tables would sit under the model's units."""
    axes = sorted({str(r.get("axis")) for r in cv.get("records") or [] if isinstance(r, dict)})
    unknown = [str(a) for a in axes if a not in model.layout.labels]
    if unknown:
        raise InputError(f"{source}: scores components {', '.join(map(printable, axes))}; the model's "
                         f"are {', '.join(model.layout.labels)}: give the cv.json of its calibration")
    settings = cv.get("settings") if isinstance(cv.get("settings"), dict) else {}
    own = model.settings.to_dict().get("units")
    if settings.get("units") != own:
        raise InputError(f"{source}: is in {_unit_words(settings.get('units'))}, the model in "
                         f"{_unit_words(own)}: give the cv.json of its calibration")


def _certificate_link(href: str | None) -> str:
    """The report's pointer to the calibration certificate: a link where one was given."""
    what = "Calibration certificate (ISO&nbsp;376 figures, class, uncertainty budget)"
    if href is None:
        return (f'<p id="certificate-link">{what}: written by <code>fsdecouple certificate MODEL '
                "CALIB -o FILE.html</code>.</p>\n")
    return (f'<p id="certificate-link">{what}: <a href="{html.escape(quote(href), quote=True)}">'
            f"{escape(href, keep='')}</a>.</p>\n")


def build_report(model, cv: dict | None = None, calib=None, certificate: str | None = None
                 ) -> Report:
    """Render the calibration report of ``model``.

    Parameters
    ----------
    model : CouplingErrorModel
    cv : dict, optional
        A cv.json document (:func:`load_cv_results`).
    calib : CalibrationSet, optional
        The calibration set, to plot its points.
    certificate : str, optional
        Where the report links its certificate (a link relative to the report's
        directory, ``report --certificate``); without it, the command that writes one.
    """
    model.layout.one_output_each("report")
    if getattr(model, "imported", False):
        from ..errors import InputError

        raise InputError("report: the model is an imported factory matrix (docs/ati.md), with no "
                         "fit, chi or calibration of its own to report; validate it on your set")
    if cv is not None:
        check_cv_fits(model, cv)
    figs: dict[str, bytes] = {}
    body = [f"<h1>Calibration report: {escape(model.settings.sensor, keep='')}</h1>\n",
            _header(model, cv),
            _certificate_link(certificate)]
    if model.warnings:
        body.append("<ul>" + "".join(f"<li>warning: {escape(w)}</li>" for w in model.warnings) + "</ul>\n")

    points, where = _point_roles(model, calib, cv) if calib is not None else (None, "")
    shown = _shown(model.settings.units)
    body.append("<h2>Non-coupling functions ω (Figure 6)</h2>\n")
    figs["figure6_omega"] = to_png(omega_figure(model, points))
    body.append(figure_html(
        "fig-omega", figs["figure6_omega"], "Figure 6: prime output against prime load per axis",
        f"Per axis: prime output [{shown['output']}] against prime load [{shown['load']}] of that "
        "axis's sweeps and the fitted line of the model file (eq. 2); slope k, 1/k (eq. 13) and R². "
        + (f"Points {where}; lower row: deviation from the line [{shown['small']}]." if calib is not None
           else "No calibration points: pass --calib CALIB to plot them.")))
    body.append(_model_tables(model))
    body.append(temperature_html(model))  # issue 31: '' without temperature terms

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
        f"Each χab: coupling error eab on output a [{shown['small']}] against the prime output ub "
        f"[{shown['output']}]. {src}. "
        + (f"Points {where}." if calib is not None else "No calibration points: pass --calib CALIB "
           "to plot the training and held-out points.")))

    body.append("<h2>Interference error γ (Tables 1, 3 and 5)</h2>\n")
    if cv:
        held = "held-out load level" if cv.get("protocol") == "levels" else "held-out repetition"
        body.append(note("Cells marked ▲ (bold, boxed) are worse than the initial data of the same "
                         f"{held}."))
        body.append(gamma_tables(cv))
        body.append(gross_tables(cv))
        body.append("<h2>Combined loads</h2>\n")
        body.append(task_table(cv))
    else:
        body.append(note("No cross-validation results: run fsdecouple cv CALIB -o cv.json and pass "
                         "--cv cv.json to add Tables 1, 3 and 5 and the combined-load comparison."))

    body.append("<h2>Assumption checks</h2>\n")
    body.append(_checks(model, cv))

    body.append("<h2>Residuals</h2>\n")
    residuals = _cv_residuals(cv) if cv else None
    if residuals is not None:
        held = "load level" if _levels(cv) else "repetition"
        title = f"Decoupled load error of each held-out {held} (ε-SVR, cross-validation)"
        cap = (f"Decoupled minus applied load [{shown['load']}] against the applied load, per loaded "
               f"axis (rows) and component (columns); one series per held-out {held}, each "
               "decoupled by the model of the round that held it out.")
    elif calib is not None:
        residuals = _calib_residuals(model, calib)
        title = "Decoupled force error on the calibration data (in-sample, not held out)"
        cap = (f"Decoupled minus applied load [{shown['load']}] against the applied load, per loaded "
               "axis (rows) and component (columns), one series per repetition. These points "
               "trained the model: pass --cv cv.json for held-out residuals.")
    if residuals is not None:
        figs["residuals"] = to_png(residual_figure(residuals, title, model.settings.load_unit))
        body.append(figure_html("fig-residuals", figs["residuals"], "Residual plot", cap))
    else:
        body.append(note("No residual plot: pass --cv cv.json or --calib CALIB."))

    body.append("<h2>Provenance and settings</h2>\n")
    body.append(_provenance(model, cv, calib))

    html = ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            f"<title>fsdecouple calibration report: {escape(model.settings.sensor, keep='')}</title>\n"
            f"<style>{CSS}</style>\n</head>\n<body>\n" + "".join(body) + "</body>\n</html>\n")
    return Report(html, figs)
