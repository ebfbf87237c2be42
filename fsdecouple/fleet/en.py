"""E_n between two calibrations of one sensor: a change told apart from the scatter.

At every calibrated step of each component, of either calibration,

    E_n = (F_A - F_B) / sqrt(U_A^2 + U_B^2)

(ISO/IEC 17043:2010, B.4.1.1; EURAMET cg-4 uses it to compare force calibrations),
with F_A and F_B the decoupled prime force of that step's mean outputs under model A
and under model B, and U_A, U_B their expanded uncertainties (k = 2) at that load
(the step's own U from the model that calibrated it, the other model's interpolated
over its steps).  Both models decouple the *same* outputs: A's step means under A
and under B, and B's under both; a calibration whose outputs are all 1 % larger
decouples its own steps perfectly, and only the crossing shows the change.
|E_n| <= 1: the calibrations agree within their uncertainties.

The step means and U come from the model file's ``report.certificate`` (written by
``fit``); a model without them (an older file, or ``--no-verdict``) gives no E_n.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..core.model import CouplingErrorModel


def _steps(model: CouplingErrorModel) -> dict[str, dict] | None:
    cert = model.report.certificate if model.report is not None else None
    return None if not cert else cert.get("steps")


def en_figures(a: CouplingErrorModel, b: CouplingErrorModel, names=("old", "new")
               ) -> tuple[dict[str, Any] | None, str | None]:
    """``({"en": {component: max |E_n|}, "steps": [...]}, None)``, or ``(None, why not)``."""
    sa, sb = _steps(a), _steps(b)
    missing = [n for n, s in zip(names, (sa, sb), strict=True) if s is None]
    factory = [getattr(m, "imported", False) for m in (a, b)]
    note = None
    if len(missing) == 1 and factory[names.index(missing[0])]:
        # an imported factory matrix (data/ati_cal.py) states no uncertainty: E_n at the
        # other calibration's steps with U = 0 for the factory's, an upper bound on |E_n|
        def zero(m):
            return {axis: {"load": [], "U": []} for axis in m.layout.labels}
        sa, sb = (zero(a), sb) if sa is None else (sa, zero(b))
        note = (f"the {missing[0]} model is a factory matrix with no stated uncertainty: E_n "
                f"at the other's steps with U_{missing[0]} = 0 (|E_n| is at most this)")
    elif all(factory):
        return None, "both models are factory matrices with no stated uncertainty: no E_n"
    elif missing:
        from ..core.modelfile import why_no_certificate

        model = a if sa is None else b
        return None, (f"the {' and '.join(missing)} model file has no certificate data "
                      f"({why_no_certificate(model)}): no E_n; gate by --max-drift")
    out, steps = {}, []
    for i, axis in enumerate(a.layout.labels):
        worst = 0.0
        # by position: the names may be ATI's torques in one and moments in the other
        # (fleet/drift.py checks they are one sensor's)
        da, db = sa[axis], sb[b.layout.labels[i]]
        for own, data, other in ((names[0], da, db), (names[1], db, da)):
            if not data["load"]:
                continue  # the factory matrix's: no steps of its own
            loads = np.asarray(data["load"], dtype=float)
            outputs = np.asarray(data["outputs"], dtype=float)
            f_a = a.decouple(outputs, rotate=False, exact=True)[:, i]
            f_b = b.decouple(outputs, rotate=False, exact=True)[:, i]
            u_own = np.asarray(data["U"], dtype=float)
            order = np.argsort(other["load"])
            u_other = np.interp(loads, np.asarray(other["load"], dtype=float)[order],
                                np.asarray(other["U"], dtype=float)[order]) if other["load"] \
                else np.zeros_like(loads)
            u_a, u_b = (u_own, u_other) if own == names[0] else (u_other, u_own)
            en = (f_a - f_b) / np.hypot(u_a, u_b)  # hypot: U of 1e-200 squares to 0
            worst = max(worst, float(np.abs(en).max(initial=0.0)))
            steps += [{"axis": axis, "load": float(f), "steps_of": own, f"F_{names[0]}": float(x),
                       f"F_{names[1]}": float(y), f"U_{names[0]}": float(p), f"U_{names[1]}": float(q),
                       "en": float(e)}
                      for f, x, y, p, q, e in zip(loads, f_a, f_b, u_a, u_b, en, strict=True)]
        out[axis] = worst
    return {"en": out, "steps": steps}, note
