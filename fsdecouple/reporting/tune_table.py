"""The table of ``fit --tune`` and ``cv --tune``: every candidate's held-out figure.

Apart from :mod:`fsdecouple.reporting.console` to keep each module one screenful of ideas;
built from the ``tune`` record of :mod:`fsdecouple.evaluation.tune`, in the data's load unit.
"""

from __future__ import annotations

from typing import Any

from rich.table import Table
from rich.text import Text

from ..config import SVRSettings
from ..core.metrics import pct
from .words import svr_unit


def tune_table(record: dict[str, Any], load_unit: str, output_unit: str = "V") -> Table:
    """One row per candidate: gamma, C, epsilon (and the units they are in: full-scale
    outputs, or with ``scaling: none`` the outputs' own, ``output_unit``), held-out RMS per
    axis, figure, choice."""
    cands = record["candidates"]
    axes = list(cands[0]["rms"])
    sigma = record["noise"]
    noise = f"sigma {pct(sigma, 3)} F.S." if sigma is not None else "no repeats: fixed epsilon"
    t = Table(title=f"SVR settings by held-out error ({record['protocol']} protocol, "
                    f"{record['rounds']} rounds, K = {record['refine']}; {noise})")
    edge = any(c.get("edge") is not None for c in cands)  # records from before: no column
    for col in ("#", "gamma", "C", "epsilon", "units",
                *(f"RMS {a} [{load_unit}]" for a in axes), "worst % F.S.",
                *(["edge % F.S."] if edge else []), ""):
        t.add_column(col, justify="left" if col in ("units", "") else "right")
    for i, c in enumerate(cands):
        rms = [f"{c['rms'][a]:.4g}" if c["rms"][a] is not None else "–" for a in axes]
        own = svr_unit(c.get("scaling", "full_scale"), output_unit)
        if c["table2"]:  # candidate 0: the settings a plain fit uses
            t2 = SVRSettings(C=c["C"], epsilon=c["epsilon"], gamma=c["gamma"]).table2
            units = f"{'Table 2' if t2 else 'as configured'}, {own}"
        else:
            units = own
        if c.get("tolerance") is not None:  # before the tuned tolerance: none; None: fit's rule
            units += f", tol {c['tolerance']:g}"
        note = Text("chosen", "bold green") if i == record["chosen"] else Text(
            "clearly better" if c["clearly_better"] else "")
        t.add_row(str(i), f"{c['gamma']:g}", f"{c['C']:g}", f"{c['epsilon']:.3g}", units, *rms,
                  pct(c["figure"], 4), *([pct(c.get("edge"), 4)] if edge else []), note)
    return t
