"""What ``fsdecouple validate`` prints: the model, the least-squares matrix and ``initial``
side by side, per range and loaded axis, from the validation document.

Apart from :mod:`fsdecouple.reporting.console` to keep each module one screenful of ideas.
"""

from __future__ import annotations

from typing import Any

from rich.table import Table
from rich.text import Text

from ..axes import labels_in
from ..errors import printable

NO_FIGURE = "-"  # a group without a loaded point has no figure (value null)


def _pct(fraction: float | None) -> str:
    return NO_FIGURE if fraction is None else f"{100.0 * fraction:.2f}"


def _abs(value: float | None) -> str:
    return NO_FIGURE if value is None else f"{value:.4g}"


def _initial(how: str | None) -> str:
    """The legend's words on the initial rows: none for an imported factory matrix."""
    if how is None:
        return ""
    gauges = " (the least-squares loads of the gauges)" if how == "f = P u" else ""
    return f"; initial: {how}{gauges}"


def validation_renderables(doc: dict[str, Any], output=None, *, as_json: bool = False) -> list:
    """Everything ``fsdecouple validate`` prints, as (to_stderr, renderable) pairs.

    Text from files (paths, unit names, warnings) is always a :class:`Text`, so
    rich never reads it as markup.  ``n``: the points behind max and RMS (gamma's,
    when fewer, in brackets: combined-load points have no gamma).
    """
    from ..evaluation.validate import METHODS, RANGES, dumps

    out: list = []
    if as_json:
        out.append((False, Text(dumps(doc))))
    unit = doc["units"]["load"]
    mixed = " / " in unit  # forces and moments: an error over every component has no one unit
    by = {(r["range"], r["axis"], r["method"], r["metric"]): r for r in doc["records"]}
    methods = [m for m in METHODS if any(r["method"] == m for r in doc["records"])]
    for rng in RANGES if not as_json else ():
        axes = [a for a in labels_in(doc["records"])
                if any((rng, a, m, "max_error") in by for m in methods)]
        if not axes:
            continue
        t = Table(title=Text(f"{rng} points of {doc['set']['path']}, model {doc['model']}: "
                             f"% F.S.{'' if mixed else f' and {unit}'}"))
        absolute = () if mixed else (f"max [{unit}]", f"RMS [{unit}]")
        for col in ("axis", "method", "n", "γ % F.S.", "max % F.S.", "RMS % F.S.", *absolute):
            t.add_column(Text(col), justify="right")
        for a in axes:
            for m in methods:
                gamma, *errs = [by.get((rng, a, m, metric))
                                for metric in ("gamma", "max_error", "rms_error")]
                n = str(errs[0].get("n", "?"))
                if gamma is not None and gamma.get("n") not in (None, errs[0].get("n")):
                    n += f" ({gamma['n']})"
                t.add_row(a, m, n, _pct(None if gamma is None else gamma["value"]),
                          *(_pct(r["value"]) for r in errs),
                          *(() if mixed else (_abs(r["value_load_unit"]) for r in errs)))
        out.append((False, t))
    if not as_json:
        in_unit = (f"components in {unit} have no one unit, so the errors are in % F.S. only"
                   if mixed else f"in {unit}: the same fraction of the largest full scale")
        out.append((False, Text(
            "model: the model file's method; linear: the least-squares matrix f = C u fitted on "
            f"the same calibration{_initial(doc.get('initial', 'f = u / k'))}. gamma: eq. (12) "
            "on each loaded axis's "
            "points; max, RMS: |f_c - F_c| / F_c(FS) over those points and every component c; "
            f"{in_unit}. n: the points behind each figure ('{NO_FIGURE}': no loaded point, no "
            "figure). calibrated: every output within the calibrated range +/- 1 % of its span.")))
    g = doc["gate"]
    if g is not None:
        worst = "no calibrated point" if g["worst"] is None else f"{_pct(g['worst'])} % F.S."
        line = Text(f"gate: worst model gamma on calibrated points {worst}, --max-gamma "
                    f"{_pct(g['max_gamma'])} % -> {'passed' if g['passed'] else 'FAILED'}",
                    style="" if g["passed"] else "bold red")
        out.append((as_json or not g["passed"], line))
    t = doc.get("temperature")
    if t is not None and not as_json:  # a fitted model's terms: the set corrected to T0
        terms = "; ".join(f"{o} b {t['b'][o]:+.4g} {doc['units']['output']}/K, g "
                          f"{1e6 * t['g'][o]:+.1f} ppm/K" for o in t["b"])
        out.append((False, Text(f"outputs corrected to T0 = {t['t0']:g} degC by the model's "
                                f"temperature terms: {terms}")))
    if output is not None and not as_json:
        out.append((False, Text(f"validation document written to {printable(output)}")))
    out += [(True, Text("warning: ", style="yellow") + Text(w)) for w in doc["warnings"]]
    return out
