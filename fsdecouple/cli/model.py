"""Commands that make and read model files: fit, show, export."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.progress import MofNCompleteColumn
from rich.text import Text

from ..config import load_config
from ..core.metrics import check_max_gamma
from ..core.modelfile import load_model, save_model
from ..errors import ConfigError, InputError, printable
from ..files.outputs import check_output, refuse_overwriting_input
from ..reporting.console import fit_checks_table, fit_tables
from .app import (
    ConfigOpt,
    ForceOpt,
    JsonOpt,
    _given,
    _read,
    app,
    ascii_digits,
    console,
    err_console,
    output_file,
    print_json,
    progress_bar,
    user_errors,
    warn,
)


@app.command()
def fit(
    calib: Annotated[Path, typer.Argument(help="Calibration directory or CSV.")],
    output: Annotated[Path, output_file("Model file to write (JSON).")],
    config: ConfigOpt = None,
    C: Annotated[float | None, typer.Option("--C", help="SVR regularisation C.")] = None,
    epsilon: Annotated[float | None, typer.Option(
        help="SVR epsilon (in full-scale units with scaling: full_scale, else output units).")] = None,
    gamma: Annotated[float | None,
                     typer.Option(help="SVR kernel width: libsvm gamma = 1/(2 delta^2).")] = None,
    delta2: Annotated[float | None, typer.Option(help="RBF delta^2.")] = None,
    tolerance: Annotated[float | None, typer.Option(help="libsvm stopping tolerance.")] = None,
    scaling: Annotated[str | None, typer.Option(help="Kernel input scaling: none|full_scale.")] = None,
    max_gamma: Annotated[
        float | None,
        typer.Option(help="Exit 1 if any interference error (eq. 12) after decoupling "
                          "exceeds this fraction."),
    ] = None,
    method: Annotated[
        str | None, typer.Option(help="svr (the paper's), linear (calibration matrix) or auto "
                                      "(the lower held-out error); default: the config's "
                                      "method, else svr.")
    ] = None,
    exclude: Annotated[
        list[str] | None,
        typer.Option(metavar="FILE:LINE", help="Drop line LINE of FILE (header = line 1; "
                                             "repeatable), e.g. a gross error fit flagged, "
                                             "even a line that cannot be read.",
                     callback=ascii_digits)
    ] = None,
    refine: Annotated[
        int | None, typer.Option(help="Second-order refinement steps K stored in the model "
                                      "(0: eq. (11) as the paper writes it).")
    ] = None,
    tune: Annotated[
        bool, typer.Option("--tune", help="Choose gamma, C and epsilon by held-out error from "
                                          "a grid (Table 2 is one candidate).")
    ] = False,
    tune_grid: Annotated[
        str | None, typer.Option(help='The --tune grid, e.g. "gamma=1,2,4,8;C=1,10;'
                                      'epsilon=0.25,0.5,1" (epsilon: multiples of the noise).',
                                 callback=ascii_digits)
    ] = None,
    extrapolation: Annotated[
        str | None, typer.Option(help="chi beyond its calibrated range: tangent (continued "
                                      "along its tangent at the edge; default) or kernel "
                                      "(the kernel sum, which decays to -rho).")
    ] = None,
    no_verdict: Annotated[
        bool, typer.Option("--no-verdict", help="Skip the held-out comparison with the "
                                                "calibration matrix.")
    ] = False,
    strict: Annotated[
        bool, typer.Option("--strict", help="Refuse rows whose applied loads are blank "
                                            "(default: skip them with a warning).")
    ] = False,
    prior: Annotated[
        Path | None, typer.Option(help="A previous model of the same sensor: fit shrinks "
                                       "toward it, by as much as held-out error chooses "
                                       "(in-situ recalibration with few poses).")
    ] = None,
    force: ForceOpt = False,
    json_out: JsonOpt = False,
) -> None:
    """Fit the coupling error model, judge it on held-out points, write one JSON model file."""
    from ..data.calibration import load_calibration
    from ..evaluation.calibrate import fit as fit_model
    from ..evaluation.calibrate import fit_document
    from ..evaluation.checks import assumption_checks
    from ..evaluation.tune import grid_option, tunable
    from ..evaluation.verdict import verdict_line
    from ..reporting.advice import refine_advice, tune_advice
    from ..reporting.tune_table import tune_table

    with user_errors():
        settings = load_config(
            config, C=C, epsilon=epsilon, gamma=gamma, delta2=delta2, tolerance=tolerance,
            scaling=scaling, refine=refine, extrapolation=extrapolation,
        )
        check_max_gamma(max_gamma)
        grid = grid_option(tune, tune_grid)
        check_output(output, force=force)
        cs = load_calibration(calib, settings, exclude=exclude or (), strict=strict)
        refuse_overwriting_input(output, [*_read(cs), *_given(config), *_given(prior)])
        with progress_bar("tuning" if tune else "fitting", MofNCompleteColumn()) as progress:
            def refit(c):
                return fit_model(c, settings, method=method, verdict=not no_verdict, tune=tune,
                                 tune_grid=grid, progress=progress)
            if prior is not None:  # fitting/prior.py: lambda chosen by held-out error
                from ..core.modelfile import load_model
                from ..fitting.prior import fit_with_prior

                model = fit_with_prior(cs, settings, load_model(prior), printable(prior), refit,
                                       method=method, tune=tune)
            else:
                model = refit(cs)
        checks = assumption_checks(model)
        advice = refine_advice(checks, model.n_components)
        advice["tune"] = tune_advice(advice, model.report.tune, can_tune=tunable(cs),
                                     linear=model.method == "linear")
        save_model(model, output, force=force)
    if json_out:
        print_json(fit_document(model, output, checks, advice))
    else:
        if model.report.tune is not None:
            console.print(tune_table(model.report.tune, model.settings.load_unit,
                                     model.settings.output_unit))
        for t in [*fit_tables(model), fit_checks_table(checks)]:
            console.print(t)
        if model.method == "linear":  # the matrix decouples: eq. (11)'s refinement is moot
            console.print("second-order coupling error (eq. 6): not used; the model decouples "
                          "by the least-squares calibration matrix")
        else:
            console.print(_refine_line(advice, settings.refine))
        if model.report.verdict is not None:
            console.print(verdict_line(model.report.verdict))
        console.print(f"model written to {printable(output)} (decouples by {model.method})")
        if not model.layout.overdetermined:  # report refuses M > N outputs (docs/rigs.md)
            console.print(f"calibration report: fsdecouple report {printable(output)} -o report.html")
    warn(model.warnings)
    if max_gamma is not None:
        worst = max(model.report.gamma_after.values())
        if worst > max_gamma:
            err_console.print(
                Text("gate failed: ", "red") + Text(f"gamma after decoupling {100 * worst:.3f} % F.S. "
                                                    f"exceeds --max-gamma {100 * max_gamma:.3f} %")
            )
            raise typer.Exit(1)


def _refine_line(advice: dict, refine: int) -> str:
    k, tune = advice["recommended"], advice.get("tune") or {}
    line = (f"second-order coupling error (eq. 6): at most {100 * advice['second_order']:.3f} % "
            f"F.S. (chi_{advice['chi']}); model refine: K = {refine}")
    if k == 0:
        return f"{line} (within {100 * advice['target']:.2f} % F.S., eq. (11) as written is enough)"
    if k is None:
        return (f"{line}; max |dchi/du| = {advice['slope']:.3f}: refinement is not known to "
                "converge, check the sensor's coupling")
    within = f"brings it within {100 * advice['target']:.2f} % F.S."
    if tune.get("basis") == "linear":  # a matrix has no chi to refine or tune
        return line
    if tune.get("basis") == "coupling":  # untuned: tune_advice
        why = "--tune chooses the SVR settings by held-out error"
        if refine < k:
            return f"{line}; recommended: --tune --refine {k} (refinement {within}; {why})"
        return f"{line}; recommended: --tune ({why})"
    if tune.get("basis") == "heldout":
        held = (f"--tune's choice is {100 * tune['gain']:.0f} % below Table 2 on held-out points"
                if tune["recommended"] and tune["gain"] is not None
                else "--tune kept Table 2 (no setting clearly better on held-out points)")
        return f"{line}; {held}" + (f"; recommended: --refine {k} ({within})" if refine < k else "")
    if refine >= k:
        return line
    return f"{line}; recommended: --refine {k} ({within})"


@app.command()
def show(model_file: Annotated[Path, typer.Argument(help="Model file (JSON).")]) -> None:
    """Print a model file's slopes, SVRs and fit report."""
    with user_errors():
        model = load_model(model_file)
    for t in fit_tables(model):
        console.print(t)
    warn(model.warnings)


@app.command()
def export(
    model_file: Annotated[Path, typer.Argument(help="Model file (JSON).")],
    output: Annotated[Path, output_file("File to write: a C header (decoupler.h), or an ATI "
                                        "calibration file (sensor.cal), chosen by the suffix.")],
    precision: Annotated[
        str, typer.Option(help="double: fsd_decouple; float: fsd_decouple_f with float tables.")
    ] = "double",
    prefix: Annotated[str, typer.Option(help="Prefix of every C name (macros: uppercased).")] = "fsd_",
    max_error: Annotated[
        float | None,
        typer.Option(help="Coarsest tables keeping this force error (fraction of full-scale load)."),
    ] = None,
    linear_part: Annotated[bool, typer.Option(
        "--linear-part", help=".cal of a nonlinear model: write its omega matrix and print what "
                              "it loses in % F.S.")] = False,
    force: ForceOpt = False,
    json_out: JsonOpt = False,
) -> None:
    """Export the model as one dependency-free C99 header (eq. 11, or a linear model's matrix),
    or, for an output ending in .cal, as an ATI calibration file (ATIDAQ loads it)."""
    if output.suffix.lower() == ".cal":
        _export_cal(model_file, output, linear_part, force, json_out,
                    precision != "double" or prefix != "fsd_" or max_error is not None)
        return
    from ..export.header import export_header

    with user_errors():
        if output.suffix.lower() not in HEADER_SUFFIXES:  # the suffix chooses the format
            raise InputError(f"{printable(output)}: expected a C header "
                             f"({', '.join(HEADER_SUFFIXES)}) or an ATI calibration file (.cal); "
                             "the suffix chooses the format")
        if linear_part:
            raise ConfigError("--linear-part: for a .cal output only; the C header exports the "
                              "model whole")
        model = _exporting(model_file, output, force)
        result = export_header(model, output, precision=precision, prefix=prefix,
                               max_error=max_error, force=force)
    if json_out:
        print_json(result.to_dict())
        return
    for line in result.summary_lines():
        console.print(line, highlight=False, soft_wrap=True)
    if model.report is not None and model.report.certificate:
        console.print("note: the header decouples forces only; apply --interval's bounds are not "
                      "in it (docs/certificate.md)", highlight=False, soft_wrap=True)
    if model.zero is not None and model.temperature is not None:
        # zero: intercept with temperature terms: the header's zero is set_zero's reading only
        zero = ", ".join(f"{c}={v:.6g}" for c, v in zip(model.layout.outputs, model.zero, strict=True))
        console.print(f"note: the header decouples zero-corrected outputs; subtract this model's "
                      f"fitted offsets first ({zero} {model.settings.output_unit})",
                      highlight=False, soft_wrap=True)


HEADER_SUFFIXES = (".h", ".hh", ".hpp", ".hxx", ".inc")


def _exporting(model_file: Path, output: Path, force: bool):
    """The model to export, once ``output`` may be written (not an existing file without
    ``force``, never the model itself)."""
    model = load_model(model_file)
    check_output(output, force=force)
    refuse_overwriting_input(output, [model_file])
    return model


def _export_cal(model_file: Path, output: Path, linear_part: bool, force: bool, json_out: bool,
                header_options: bool) -> None:
    from ..export.ati_cal import export_cal

    with user_errors():
        if header_options:
            raise ConfigError("--precision, --prefix and --max-error: for a C header; a .cal holds "
                              "the matrix in full")
        model = _exporting(model_file, output, force)
        result = export_cal(model, output, source=printable(model_file), linear_part=linear_part,
                            force=force)
    if json_out:
        print_json({k: v for k, v in result.items() if k != "lines"})
        return
    for line in result["lines"]:
        console.print(line, highlight=False, soft_wrap=True)
