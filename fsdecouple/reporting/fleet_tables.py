"""The tables of the fleet commands: ``compare`` (drift) and ``fit-many``.

Apart from :mod:`fsdecouple.reporting.console` to keep each module one screenful of ideas;
like it, built from documents, with no computation beyond picking numbers.
"""

from __future__ import annotations

from typing import Any

from rich.table import Table
from rich.text import Text

from ..core.metrics import pct

FAILED = "bold red"


def _signed(v: float | None) -> str:
    return "-" if v is None else f"{v:+.3f} %"


def drift_table(doc: dict[str, Any]) -> Table:
    """Per component: slope change, chi differences, force difference [%]."""
    gate = doc["max_drift"]
    old, new = doc["old"], doc["new"]
    t = Table(title=f"Drift of {new['model'] or 'the new model'} against {old['model'] or 'the old model'}"
                    f" (chi: % of full-scale output; force: % of full-scale load)")
    for col in ("component", "slope change (eq. 2)", "chi, largest difference (eq. 4)",
                "force, largest difference (eq. 11)"):
        t.add_column(col, justify="right")

    def cell(v: float | None, text: str) -> Text:
        if v is None:  # an imported factory matrix has no slopes (fleet/drift.py)
            return Text("-")
        return Text(text, style=FAILED if gate is not None and abs(v) > gate else "")

    temp = doc.get("temperature")
    if temp:  # temperature terms (core/temperature.py): their change, new - old
        t.caption = temp.get("note") or (
            f"temperature terms, new - old: T0 {temp['t0_change']:+.4g} {temp['unit']}; " + "; ".join(
                f"{o} b {temp['b_change'][o]:+.3g} {doc['units']['output']}/{temp['unit']}, "
                f"g {temp['g_change'][o]:+.3g} 1/{temp['unit']}" for o in temp["b_change"]))
    for a, c in doc["components"].items():
        chi = Text(", ").join(cell(v, f"{name} {v:.3f} %") for name, v in c["chi_max_pct"].items())
        t.add_row(a, cell(c["slope_change_pct"], _signed(c["slope_change_pct"])), chi,
                  cell(c["force_max_pct"], f"{c['force_max_pct']:.3f} %"))
    return t


def drift_line(doc: dict[str, Any]) -> str | None:
    """The gate's verdict, or None without ``--max-drift``."""
    en = doc.get("en")
    en_text = None if en is None else "largest |E_n| " + ", ".join(f"{a} {v:.2f}" for a, v in en.items())
    if doc["passed"] is None:
        return f"note: {doc['en_note']}" if doc.get("en_note") else None
    gates = " or ".join(([f"--max-drift {doc['max_drift']:g} %"] if doc["max_drift"] is not None
                         else []) + (["|E_n| > 1"] if doc.get("en_gate") else []))
    # a note beside E_n figures says how they were made (a factory matrix: U = 0 for it)
    note = f"; note: {doc['en_note']}" if en_text and doc.get("en_note") else ""
    if doc["passed"]:
        return f"no change exceeds {gates}" + (f" ({en_text})" if en_text else "") + note
    return (f"changed beyond {gates}: {'; '.join(doc['exceeded'])}" + (f" ({en_text})" if en_text
                                                                       else "") + note)


def fleet_table(doc: dict[str, Any]) -> Table:
    """One row per sensor: slopes, held-out worst gamma, verdict, warnings, drift, result."""
    t = Table(title=f"fit-many {doc['sensors_dir']} -> {doc['models_dir']}")
    for col in ("sensor", "k (eq. 2)", "held-out worst gamma", "better on held-out",
                "warnings", "largest drift", "result"):
        t.add_column(col, justify="left" if col in ("sensor", "result") else "right")
    for s in doc["sensors"]:
        if s["error"] is not None:
            t.add_row(s["sensor"], "", "", "", "", "", Text("error (see below)", FAILED))
            continue
        per = s["units"].get("k") or {}  # fleet documents before it: one unit for all
        values = ", ".join(f"{v:.6g}" for v in s["k"].values())
        if len(set(per.values())) > 1:  # forces and moments: each k with its own unit
            k = ", ".join(f"{v:.6g} {per[name]}" for name, v in s["k"].items())
        elif per and not any(per.values()):  # more gauges than loads: pure numbers
            k = values
        else:
            k = f"{values} {s['units']['output']}/{s['units']['load']}"
        drift = "" if s["drift"] is None else f"{_largest(s['drift']):.3f} %"
        result = Text("gate failed", FAILED) if s["gate"] else Text("ok")
        t.add_row(s["sensor"], k, f"{pct(s['worst_gamma'], 3)} ({s['method']})", s["better"] or "–",
                  str(len(s["warnings"])), drift, result)
    return t


def fleet_errors(doc: dict[str, Any]) -> list[str]:
    """One line per sensor that could not be fitted."""
    return [f"{s['sensor']}: {s['error']}" for s in doc["sensors"] if s["error"] is not None]


def fleet_warnings(doc: dict[str, Any]) -> list[str]:
    """Each fitted sensor's warnings, one line each, named by the sensor (the table counts
    them)."""
    return [f"{s['sensor']}: {w}" for s in doc["sensors"] if s["error"] is None
            for w in s["warnings"]]


def fleet_gate_lines(doc: dict[str, Any]) -> list[str]:
    """One line per sensor that fails --max-gamma or --max-drift, naming it."""
    return [f"{s['sensor']}: {'; '.join(s['gate'])}" for s in doc["sensors"]
            if s["error"] is None and s["gate"]]


def _largest(drift: dict[str, Any]) -> float:
    return max(max(abs(c["slope_change_pct"] or 0.0), abs(c["force_max_pct"]),
                   *c["chi_max_pct"].values())
               for c in drift["components"].values())


def apply_many_table(doc: dict[str, Any]) -> Table:
    """One row per input log: its output, rows, status counts (those that occur), result."""
    t = Table(title=f"apply ({doc['engine']}) -> {doc['output_dir']}, forces in {doc['force_unit']}")
    for col in ("input", "output", "rows", "statuses", "result"):
        t.add_column(col, justify="right" if col == "rows" else "left")
    for f in doc["files"]:
        if f["error"] is not None:
            t.add_row(f["input"], "", "", "", Text("error (see below)", FAILED))
            continue
        counts = ", ".join(f"{k} {v:,}" for k, v in f["status_counts"].items() if v)
        t.add_row(f["input"], f["output"], f"{f['rows']:,}", counts, Text("ok"))
    return t


def apply_many_errors(doc: dict[str, Any]) -> list[str]:
    """One line per input that failed; nothing was written for it."""
    return [f"{f['input']}: {f['error']}" if not f["error"].startswith(f["input"]) else f["error"]
            for f in doc["files"] if f["error"] is not None]
