"""The temperature terms as ``fit``, ``validate`` and ``report`` print them (issue 31)."""

from __future__ import annotations

from rich.table import Table


def temperature_tables(model) -> list:
    """b_i and g_i per output with their uncertainties, in the output's unit per kelvin,
    and the fit's held-out figure; nothing for a model without fitted terms."""
    terms = getattr(model, "temperature", None)
    if terms is None or not terms.external:
        return []  # an imported factory matrix's terms are in its own table (tables.py)
    units, layout = model.settings.units, model.layout
    span = "" if terms.span is None else f", calibrated {terms.span[0]:.4g} .. {terms.span[1]:.4g} degC"
    t = Table(title=f"Temperature terms: u = (1 + g (T - T0)) u(T0) + b (T - T0), "
                    f"T0 = {terms.t0:g} degC{span}",
              caption="beyond the calibrated temperatures a row's status is 'extrapolated'")
    for col in ("output", f"b [{units.output}/K]", "b [% F.S./K]", "g [ppm/K]"):
        t.add_column(col, justify="right")
    u_fs = model.full_scale_output if model.projection is None else None
    for i, o in enumerate(layout.outputs):
        sb = "" if terms.b_sigma is None else f" ± {terms.b_sigma[i]:.2g}"
        sg = "" if terms.g_sigma is None else f" ± {1e6 * terms.g_sigma[i]:.2g}"
        pct = "" if u_fs is None else f"{100 * terms.b[i] / u_fs[i]:+.4f}"
        t.add_row(o, f"{terms.b[i]:+.4g}{sb}", pct,
                  f"{1e6 * terms.g[i]:+.1f}{sg}")
    out = [t]
    rep = getattr(model, "report", None)
    held = (rep.temperature or {}).get("heldout") if rep is not None and rep.temperature else None
    if held:
        h = Table(title="Held out by temperature: fitted on the other temperatures, tested on "
                        "one (tared at T0; a least-squares cubic in the outputs), worst axis "
                        "RMS error % F.S.")
        for col in ("temperature [degC]", "points", "without compensation", "with compensation"):
            h.add_column(col, justify="right")
        for r in held:
            h.add_row(f"{r['temperature']:.4g}", str(r["points"]),
                      f"{r['worst_rms_pct_fs_without']:.4f}", f"{r['worst_rms_pct_fs_with']:.4f}")
        out.append(h)
    return out




def temperature_html(model) -> str:
    """The temperature terms as an HTML section (report and certificate); '' without."""
    from .html import cell, table, th, tr

    terms = getattr(model, "temperature", None)
    if terms is None or not terms.external:
        return ""
    units, layout = model.settings.units, model.layout
    span = "" if terms.span is None else f"; calibrated from {terms.span[0]:.4g} to {terms.span[1]:.4g} degC"
    rows = []
    for i, o in enumerate(layout.outputs):
        sb = "" if terms.b_sigma is None else f" ± {terms.b_sigma[i]:.2g}"
        sg = "" if terms.g_sigma is None else f" ± {1e6 * terms.g_sigma[i]:.2g}"
        rows.append(tr(cell(o), cell(f"{terms.b[i]:+.4g}{sb}"), cell(f"{1e6 * terms.g[i]:+.1f}{sg}")))
    head = [tr(th("output"), th(f"b [{units.output}/K]"), th("g [ppm/K]"))]
    out = ["<h2>Temperature terms</h2>\n", table(
        "temperature", f"u = (1 + g (T - T0)) u(T0) + b (T - T0), T0 = {terms.t0:g} degC{span}; "
        "each output is corrected to T0 before eq. (11), rows beyond the span are 'extrapolated'",
        head, rows)]
    rep = getattr(model, "report", None)
    held = ((rep.temperature or {}).get("heldout") if rep is not None and rep.temperature else None)
    if held:
        hrows = [tr(cell(f"{r['temperature']:.4g}"), cell(str(r["points"])),
                    cell(f"{r['worst_rms_pct_fs_without']:.4f}"),
                    cell(f"{r['worst_rms_pct_fs_with']:.4f}")) for r in held]
        out.append(table("temperature-heldout", "Held out by temperature: fitted on the other "
                         "temperatures, tested on one (tared at T0; a least-squares cubic in "
                         "the outputs); worst axis RMS error % F.S.",
                         [tr(th("temperature [degC]"), th("points"), th("without"), th("with"))],
                         hrows))
    return "".join(out)
