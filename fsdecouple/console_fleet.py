"""The tables of the fleet commands: ``compare`` (drift) and ``fit-many``.

Apart from :mod:`fsdecouple.console` to keep each module one screenful of ideas;
like it, built from documents, with no computation beyond picking numbers.
"""

from __future__ import annotations

from typing import Any

from rich.table import Table
from rich.text import Text

FAILED = "bold red"


def _signed(v: float) -> str:
    return f"{v:+.3f} %"


def drift_table(doc: dict[str, Any]) -> Table:
    """Per component: slope change, chi differences, force difference [%]."""
    gate = doc["max_drift"]
    old, new = doc["old"], doc["new"]
    t = Table(title=f"Drift of {new['model'] or 'the new model'} against {old['model'] or 'the old model'}"
                    f" (chi: % of full-scale output; force: % of full-scale load)")
    for col in ("component", "slope change (eq. 2)", "chi, largest difference (eq. 4)",
                "force, largest difference (eq. 11)"):
        t.add_column(col, justify="right")

    def cell(v: float, text: str) -> Text:
        return Text(text, style=FAILED if gate is not None and abs(v) > gate else "")

    for a, c in doc["components"].items():
        chi = Text(", ").join(cell(v, f"{name} {v:.3f} %") for name, v in c["chi_max_pct"].items())
        t.add_row(a, cell(c["slope_change_pct"], _signed(c["slope_change_pct"])), chi,
                  cell(c["force_max_pct"], f"{c['force_max_pct']:.3f} %"))
    return t


def drift_line(doc: dict[str, Any]) -> str | None:
    """The gate's verdict, or None without ``--max-drift``."""
    if doc["passed"] is None:
        return None
    if doc["passed"]:
        return f"no change exceeds --max-drift {doc['max_drift']:g} %"
    return f"drift exceeds --max-drift {doc['max_drift']:g} %: {'; '.join(doc['exceeded'])}"
