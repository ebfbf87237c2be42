"""Figures of the calibration report: the analogues of the paper's Figures 6 and 7
and a residual plot of the held-out repetitions.

Each function returns a :class:`matplotlib.figure.Figure` built without pyplot
(no global state, no display needed: the Agg canvas renders it).  The figures
must read in black-and-white print, so every distinction is carried by marker
shape or line style as well as by colour.  A sensor of N components gets a
Figure 6 panel per component (rows of three) and a Figure 7 grid of its N(N - 1)
chi, a row per output; the 3-axis figures keep the paper's layout.
"""

from __future__ import annotations

import io
import json

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from ..axes import AXES
from ..units import output_display

OMEGA, CHI = r"\omega", r"\chi"  # mathtext symbols

# Figure 7 of the paper: training points blue, test I red, test II magenta.  Here
# the shapes differ too (open circle, filled triangle, open square).
ROLE_STYLE = {
    "training": dict(marker="o", ms=4, mfc="none", mec="tab:blue", mew=0.8, ls="none"),
    "test I": dict(marker="^", ms=5, mfc="tab:red", mec="black", mew=0.5, ls="none"),
    "test II": dict(marker="s", ms=4.5, mfc="none", mec="m", mew=1.2, ls="none"),
    "not used": dict(marker="x", ms=4, color="0.5", ls="none"),
}
SVR_STYLE = dict(color="black", lw=1.8, ls="-")
RBF_STYLE = dict(color="tab:red", lw=1.3, ls="--")
REP_MARKERS = ("o", "^", "s", "D", "v", "P", "X", "<", ">", "*")
REP_LINES = ("-", "--", ":", "-.")
PANEL = "abcdefghi"


SAMPLES = 9  # points of each line that a figure's contents keep


def to_png(fig: Figure, dpi: int = 110) -> bytes:
    """The figure as PNG bytes (no software tag, so the bytes depend on the figure only),
    its :func:`contents` as the PNG's ``Description`` text: what a committed figure
    shows can be checked against a new one by numbers, not by pixels."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi,
                metadata={"Software": None, "Description": json.dumps(contents(fig))})
    return buf.getvalue()


def contents(fig: Figure) -> dict:
    """What ``fig`` says: its title, each panel's title and axis labels, and each line's
    label with ``SAMPLES`` of its points, evenly spaced along it (``%.6g``)."""
    def sample(values) -> list[float]:
        v = np.asarray(values, dtype=float)
        at = np.unique(np.linspace(0, v.size - 1, SAMPLES).round().astype(int)) if v.size else []
        return [float(f"{x:.6g}") for x in v[at]]

    return {"title": fig.get_suptitle(), "panels": [
        {"title": ax.get_title(), "xlabel": ax.get_xlabel(), "ylabel": ax.get_ylabel(),
         "lines": [{"label": ln.get_label(), "x": sample(ln.get_xdata()), "y": sample(ln.get_ydata())}
                   for ln in ax.get_lines()]}
        for ax in fig.axes]}


def _label(ax, title: str, xlabel: str, ylabel: str, *, small: bool = False,
           title_size=None) -> None:
    """A panel's title and axis labels; ``small`` for the many panels of an N = 6 grid."""
    size = 9 if small else title_size
    ax.set_title(title, **({} if size is None else {"fontsize": size}))
    label = {"fontsize": 8} if small else {}  # matplotlib's own sizes unless small
    ax.set_xlabel(xlabel, **label)
    ax.set_ylabel(ylabel, **label)
    if small:
        ax.tick_params(labelsize=7)


def _legend_by_label(ax):
    handles, labels = ax.get_legend_handles_labels()
    seen = {}
    for h, lab in zip(handles, labels, strict=True):
        seen.setdefault(lab, h)
    return list(seen.values()), list(seen.keys())


def _by_role(s: pd.DataFrame):
    """Groups in drawing order: training first, so the held-out points lie on top."""
    order = {r: i for i, r in enumerate(ROLE_STYLE)}
    groups = dict(list(s.groupby("role", sort=False)))
    return sorted(groups.items(), key=lambda kv: order.get(kv[0], len(order)))


def _sub(symbol: str, index: str) -> str:
    """Mathtext for a symbol with a subscript, e.g. u_x."""
    return f"${symbol}_{{{index}}}$"


def _load_sym(label: str) -> str:
    """f_x for an axis of the default layout, a named component (mx) as it is."""
    return _sub("f", label) if label in AXES else label


def _out_sym(layout, a: int) -> str:
    """u_x for an axis of the default layout, else the output's name (u4)."""
    return _sub("u", layout.labels[a]) if layout.is_default else layout.outputs[a]


def _role_label(role: str, points: pd.DataFrame) -> str:
    reps = sorted(points.loc[points["role"] == role, "repetition"].unique())
    return f"{role} (rep {', '.join(map(str, reps))})"


def omega_figure(model, points: pd.DataFrame | None = None) -> Figure:
    """Figure 6: per axis, prime voltage against prime force with the eq. (2) line.

    Parameters
    ----------
    model : CouplingErrorModel
    points : DataFrame, optional
        Zero-corrected calibration points (``axis, repetition, fx..uz``) with a
        ``role`` column (``training``, ``test I``, ``test II``, ``not used``).
        Without it only the fitted lines are drawn.
    """
    layout = model.layout
    per = 2 if points is not None else 1  # a panel, and its residuals beneath
    blocks = -(-layout.n // 3)
    fig = Figure(figsize=(11, (6.4 if per == 2 else 3.8) * blocks), layout="constrained")
    axs = fig.subplots(per * blocks, 3, squeeze=False, sharex="col" if blocks == 1 else False,
                       gridspec_kw={"height_ratios": [2.2, 1] * blocks} if per == 2 else None)
    for extra in range(layout.n, 3 * blocks):  # the grid's unused places
        for row in range(per):
            axs[per * (extra // 3) + row, extra % 3].set_visible(False)
    lo_hi = model.calibrated_range
    units = model.settings.units
    small, small_unit = output_display(units.output)
    for a, axis in enumerate(layout.labels):
        k = model.k[a]
        top, col = per * (a // 3), a % 3
        ax = axs[top, col]
        load, out = layout.loads[a], layout.outputs[a]
        load_unit, f_sym, u_sym = units.load_of(a), _load_sym(axis), _out_sym(layout, a)
        f_line = np.sort(lo_hi[a] / k)
        if points is not None:
            res = axs[top + 1, col]
            if blocks > 1:
                res.sharex(ax)
            s = points[points["axis"] == axis]
            f = s[load].to_numpy()
            f_line = np.array([min(f.min(), f_line[0]), max(f.max(), f_line[1])])
            for role, g in _by_role(s):
                style = ROLE_STYLE.get(role, ROLE_STYLE["not used"])
                fa = g[load].to_numpy()
                ua = g[out].to_numpy()
                ax.plot(fa, ua, label=_role_label(role, points), **style)
                res.plot(fa, (ua - k * fa) * small, **style)
            res.axhline(0.0, **SVR_STYLE)
            res.set_ylabel(f"${{u_{axis} - k_{{{axis}{axis}}} f_{axis}}}$ [{small_unit}]"
                           if layout.is_default else f"{out} − k·{load} [{small_unit}]")
            res.set_xlabel(f"prime force {f_sym} [{load_unit}]")
            res.grid(True, color="0.88")
        else:
            ax.set_xlabel(f"prime force {f_sym} [{load_unit}]")
        ax.plot(f_line, k * f_line, label="fitted line u = k·f", **SVR_STYLE)
        r2 = (model.report.r2.get(axis) if model.report else None)
        k_sym = _sub('k', axis + axis) if layout.is_default else "k"
        text = (f"{k_sym} = {k:.6g} {units.output_of(a)}/{load_unit}\n"
                f"1/{k_sym} = {1 / k:.4g} {load_unit}/{units.output_of(a)}")
        if r2 is not None:
            text += f"\nR² = {r2:.6f}"
        ax.text(0.04, 0.96, text, transform=ax.transAxes, va="top", ha="left", fontsize=9,
                bbox=dict(boxstyle="round", fc="white", ec="0.6"))
        ax.set_title(f"({PANEL[a]}) {_sub(OMEGA, axis)}: {axis} sweeps, eq. (2)")
        ax.set_ylabel(f"prime output {u_sym} [{units.output_of(a)}]")
        ax.grid(True, color="0.88")
    handles, labels = _legend_by_label(axs[0, 0])
    fig.legend(handles, labels, loc="outside lower center", ncol=len(labels), frameon=False)
    if points is None:
        fig.suptitle("Non-coupling functions ω (eq. 2): fitted lines only "
                     "(no calibration points given)")
    else:
        fig.suptitle("Non-coupling functions ω (eq. 2): linear fits; lower row: residual "
                     "from the line")
    return fig


def chi_figure(model, points: pd.DataFrame | None = None, curves: dict | None = None) -> Figure:
    """Figure 7: the six corrected coupling functions chi (eq. 4), in the output unit (mV for V).

    Parameters
    ----------
    model : CouplingErrorModel
        Its chi are drawn unless ``curves`` is given.
    points : DataFrame, optional
        Calibration points with a ``role`` column, as for :func:`omega_figure`.
    curves : dict, optional
        cv.json ``curves.chi``: per chi name ``u`` [V], ``svr`` [V] and, if that
        baseline was run, ``rbf-siso`` [V].
    """
    layout = model.layout
    n = layout.n
    if layout.is_default:  # the paper's six panels
        fig = Figure(figsize=(11, 7.2), layout="constrained")
        axs = fig.subplots(2, 3).ravel()
    else:  # a row per output a, a column per input b != a
        fig = Figure(figsize=(2.7 * (n - 1), 2.4 * n + 0.8), layout="constrained")
        axs = fig.subplots(n, n - 1, squeeze=False).ravel()
    units = model.settings.units
    MV, small_unit = output_display(units.output)  # noqa: N806 (mV for volts, else as is)
    for i, name in enumerate(layout.chi_names):
        ax = axs[i]
        a, b = layout.pair(name)
        if points is not None:
            s = points[points["axis"] == layout.labels[b]]
            for role, g in _by_role(s):
                ax.plot(g[layout.outputs[b]], g[layout.outputs[a]] * MV,
                        label=_role_label(role, points),
                        **ROLE_STYLE.get(role, ROLE_STYLE["not used"]))
        c = (curves or {}).get(name)
        if c is not None:
            u = np.asarray(c["u"], dtype=float)
            ax.plot(u, np.asarray(c["svr"], dtype=float) * MV, label="ε-SVR", **SVR_STYLE)
            if c.get("rbf-siso") is not None:
                ax.autoscale_view()
                frame = ax.get_ylim()  # points and eps-SVR
                ax.plot(u, np.asarray(c["rbf-siso"], dtype=float) * MV, label="SISO RBF NN",
                        **RBF_STYLE)
                _clip_to_frame(ax, frame)
        else:
            u = np.linspace(*model.chi[name].input_range, 400)
            ax.plot(u, model.chi[name](u) * MV, label="ε-SVR", **SVR_STYLE)
        if layout.is_default:
            _label(ax, f"({PANEL[i]}) {_sub(CHI, name)}({_sub('u', name[1])}): "
                   f"load on {name[1]}, error on {_sub('u', name[0])}",
                   f"prime output {_sub('u', name[1])} [{units.output}]",
                   f"coupling error {_sub('e', name)} [{small_unit}]")
        else:
            _label(ax, f"χ {name}: load {layout.labels[b]} → {layout.outputs[a]}",
                   f"{layout.outputs[b]} [{units.output_of(b)}]",
                   f"e on {layout.outputs[a]} [{small_unit}]", small=True)
        ax.grid(True, color="0.88")
    handles, labels = _legend_by_label(axs[0])
    fig.legend(handles, labels, loc="outside lower center", ncol=len(labels), frameon=False)
    fig.suptitle("Corrected coupling functions χ (eq. 4)")
    return fig


def _clip_to_frame(ax, frame: tuple[float, float]) -> None:
    """Keep the points and the eps-SVR readable when an overfitted RBF curve runs far
    outside them: the frame grows by at most half its height and a note says so."""
    lo, hi = frame
    pad = 0.5 * (hi - lo)
    ax.autoscale_view()
    ylo, yhi = ax.get_ylim()
    if ylo < lo - pad or yhi > hi + pad:
        ax.set_ylim(max(ylo, lo - pad), min(yhi, hi + pad))
        ax.text(0.98, 0.02, "SISO RBF NN leaves the frame", transform=ax.transAxes, ha="right",
                va="bottom", fontsize=8, style="italic",
                bbox=dict(boxstyle="round", fc="white", ec="0.6"))


def residual_figure(residuals: pd.DataFrame, title: str, load_unit: str = "N") -> Figure:
    """Decoupled force error against applied load, per loaded axis and component.

    Parameters
    ----------
    residuals : DataFrame
        One row per point: ``axis`` (loaded axis), ``label`` (one series, e.g. a
        held-out repetition), ``load`` [N], ``ex, ey, ez`` decoupled minus applied
        force [N].
    title : str
        Figure title (says where the points come from).
    """
    comps = list(dict.fromkeys(residuals["axis"]))
    comps = list(AXES) if set(comps) <= set(AXES) else comps
    n = len(comps)
    if n == 3:
        fig = Figure(figsize=(11, 9.5), layout="constrained")
        # one y scale for all nine panels, so off-axis and on-axis errors compare at a glance
        axs = fig.subplots(3, 3, sharex="row", sharey=True)
    else:  # forces and moments: a y scale per panel
        fig = Figure(figsize=(2.9 * n, 2.5 * n + 0.8), layout="constrained")
        axs = fig.subplots(n, n, sharex="row", squeeze=False)
    labels = list(dict.fromkeys(residuals["label"]))
    for r, axis in enumerate(comps):
        s = residuals[residuals["axis"] == axis]
        for c, comp in enumerate(comps):
            ax = axs[r, c]
            for j, lab in enumerate(labels):
                g = s[s["label"] == lab].sort_values("load", kind="stable")
                ax.plot(g["load"], g[f"e{comp}"], label=lab, marker=REP_MARKERS[j % len(REP_MARKERS)],
                        ls=REP_LINES[j % len(REP_LINES)], lw=0.9, ms=3.5, mfc="none")
            ax.axhline(0.0, color="0.3", lw=0.8)
            kind = "on-axis" if comp == axis else "off-axis"
            if n == 3:
                _label(ax, f"{axis} loaded: error in {_sub('f', comp)} ({kind})",
                       f"applied load {_sub('F', axis)} [{load_unit}]",
                       f"{_sub('f', comp)} − {_sub('F', comp)} [{load_unit}]", title_size=10)
            else:
                _label(ax, f"{axis} loaded: error in {comp}", f"applied {axis}", f"Δ{comp}", small=True)
            ax.yaxis.set_tick_params(labelleft=True)
            ax.grid(True, color="0.88")
    handles, labs = _legend_by_label(axs[0, 0])
    fig.legend(handles, labs, loc="outside lower center", ncol=min(len(labs), 3), frameon=False)
    fig.suptitle(title)
    return fig
