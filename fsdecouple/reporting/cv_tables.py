"""The report's cross-validation tables: Tables 1, 3 and 5 analogues from cv.json."""

from __future__ import annotations

from ..axes import labels_in, load_name
from ..core.metrics import pct
from ..evaluation.cv_results import REFINED, gamma_index, scored_axes, test_name
from .html import cell, note, scrolled, table, th, tr, worse
from .words import output_unit_of

METHOD_NAMES = {"initial": "initial (ω⁻¹ only)", "linear": "linear matrix",
                "rbf-mimo": "MIMO RBF NN", "rbf-siso": "SISO RBF NN", "svr": "ε-SVR",
                REFINED: "ε-SVR, refined (cv --refine)"}


def cv_test_name(cv, rnd: int, test_set: int) -> str:
    """'test I' / 'test II': the held-out repetition's place in its round's fold.

    ``test_set`` is the held-out repetition's number (docs/cv.md, cv.json).
    """
    try:
        return f"test {test_name(cv['folds'][rnd - 1].index(test_set))}"
    except (KeyError, IndexError, ValueError, TypeError):
        return "test"


def gamma_tables(cv) -> str:
    g = gamma_index(cv.get("records"))
    labels = scored_axes(cv)  # the components scored, in the sensor's order
    keys = sorted({(r, t) for r, t, _, _ in g})
    methods = [m for m in cv.get("methods", []) if any(k[2] == m for k in g)]

    levels = cv.get("protocol") == "levels"

    def held(r, t):
        return f"level {t} (interior points)" if levels else f"{cv_test_name(cv, r, t)} (rep {t})"

    def val(r, t, m, a, index=g, base="initial"):
        v, b = index.get((r, t, m, a)), index.get((r, t, base, a))
        return cell(pct(v), m != base and worse(v, b))

    head = [tr(th("round", rowspan=2), th("held out", rowspan=2),
               *(th(f"γ{a}", span=len(methods)) for a in labels)),
            tr(*(th(METHOD_NAMES.get(m, m)) for _ in labels for m in methods))]
    rows = [tr(cell(str(r)), cell(held(r, t)), *(val(r, t, m, a) for a in labels for m in methods))
            for r, t in keys]
    # every method for every axis: wider than a page, so it scrolls rather than wrap its cells
    out = scrolled(table("table-gamma-methods", "Table 1 analogue: interference error γ (eq. 12) "
                         f"of the held-out {'load levels' if levels else 'repetitions'} "
                         f"({cv.get('protocol', 'repetitions')} protocol), every method, % F.S.",
                         head, rows))
    absent = [METHOD_NAMES[m] for m in METHOD_NAMES if m not in methods and m != REFINED]
    if absent:
        out += note("Not in cv.json (not run): " + ", ".join(absent) + ".")
    end = gamma_index(cv.get("end_records")) if levels else {}
    if end:  # the levels protocol's end points, scored apart: loads beyond the rest of a sweep
        ends = sorted({(r, t) for r, t, _, _ in end})
        rows = [tr(cell(str(r)), cell("end points"),
                   *(val(r, t, m, a, end) for a in labels for m in methods)) for r, t in ends]
        out += scrolled(table("table-gamma-end", "Held-out end points (each sweep's loads beyond "
                              "its others: the model extrapolates there), every method, % F.S.",
                              head, rows))
    if "svr" in methods:
        rows = [tr(cell(str(r)), cell(held(r, t)), *(val(r, t, "svr", a) for a in labels)) for r, t in keys]
        worst = [max((g.get((r, t, "svr", a)) or 0.0) for r, t in keys) for a in labels]
        rows.append(tr(th("worst"), cell(""), *(cell(pct(w)) for w in worst)))
        out += table("table-gamma-svr", "Table 3 analogue: γ after decoupling by the coupling "
                     "error model and ε-SVRs, % F.S.",
                     [tr(th("round"), th("held out"), *(th(f"γ{a}") for a in labels))], rows)
    return out


def gross_tables(cv) -> str:
    ge = cv.get("gross_error")
    if not ge:
        return note("No gross-error run in cv.json (fsdecouple cv --gross-error AXIS:REP:POINT:OFFSET "
                    "adds Table 5).")
    spec = ge.get("spec", {})
    clean, gross = gamma_index(cv.get("records")), gamma_index(ge.get("records"))
    labels = scored_axes(cv)  # the components scored, in the sensor's order
    keys = sorted({(r, t) for r, t, m, _ in gross if m == "svr"})
    rows = []
    for r, t in keys:
        cells = []
        for a in labels:
            c, w = clean.get((r, t, "svr", a)), gross.get((r, t, "svr", a))
            cells += [cell(pct(c)), cell(pct(w), worse(w, gross.get((r, t, "initial", a))))]
        rows.append(tr(cell(str(r)), cell(f"{cv_test_name(cv, r, t)} (rep {t})"), *cells))
    head = [tr(th("round", rowspan=2), th("held out", rowspan=2),
               *(th(f"γ{a} (ε-SVR)", span=2) for a in labels)),
            tr(*(th(x) for _ in labels for x in ("without", "with gross error")))]
    unit = output_unit_of(cv)
    out = note(f"Gross error: prime output of point {spec.get('point')} of the {spec.get('axis')} "
               f"sweep of repetition {spec.get('repetition')} moved by {spec.get('offset')} {unit} "
               "(Section 4.4).")
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


def task_table(cv) -> str:
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
    # two columns a component, six methods a round: wider than a page for six axes
    return out + scrolled(table("table-task", "Combined-load comparison: error as % of each "
                                "axis's full scale", head, rows))
