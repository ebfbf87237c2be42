"""Commands that judge a model: cv, validate, report."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.progress import MofNCompleteColumn

from ..config import load_config
from ..core.modelfile import load_model
from ..errors import InputError, printable
from ..files.outputs import atomic_files, check_output, refuse_overwriting_input
from .app import (
    ConfigOpt,
    ForceOpt,
    JsonOpt,
    ModelConfigOpt,
    _given,
    _read,
    app,
    ascii_digits,
    console,
    err_console,
    output_file,
    progress_bar,
    user_errors,
    warn,
)


@app.command()
def cv(
    calib: Annotated[Path, typer.Argument(help="Calibration directory or CSV.")],
    config: ConfigOpt = None,
    folds: Annotated[
        str | None,
        typer.Option(help='Held-out repetitions per round, e.g. "1,2;3,4;5,6" (the default).',
                     callback=ascii_digits),
    ] = None,
    output: Annotated[
        Path | None, output_file("Write the cv.json document.")
    ] = None,
    task: Annotated[
        Path | None, typer.Option(help="Combined-load voltage log (CSV) to validate on.")
    ] = None,
    task_forces: Annotated[
        Path | None, typer.Option(help="True forces of --task, row for row (CSV: fx, fy, fz).")
    ] = None,
    task_tare: Annotated[
        int | None, typer.Option(help="Zero the task voltages by the mean of their first N rows.")
    ] = None,
    gross_error: Annotated[
        str | None,
        typer.Option(help="Move one training point: AXIS:REP:POINT:OFFSET (in the output unit), "
                          "e.g. x:1:5:0.2", callback=ascii_digits),
    ] = None,
    max_gamma: Annotated[
        float | None,
        typer.Option(help="Exit 1 if any svr interference error (eq. 12) on held-out data exceeds "
                          "this fraction."),
    ] = None,
    workers: Annotated[
        int | None, typer.Option(help="Training threads (default: cores; 1: sequential).")
    ] = None,
    repeats: Annotated[int, typer.Option(help="Sequential timing passes (Table 4).")] = 1,
    protocol: Annotated[
        str | None, typer.Option(help="What a round holds out: repetitions|levels|poses "
                                      "(default: repetitions with 3 or more, else every fifth "
                                      "pose for poses of a mass, else load levels).")
    ] = None,
    tune: Annotated[
        bool, typer.Option("--tune", help="Cross-validate with SVR settings chosen as fit --tune "
                                          "chooses them (on the whole set).")
    ] = False,
    tune_grid: Annotated[
        str | None, typer.Option(help="The --tune grid (as for fit).", callback=ascii_digits)
    ] = None,
    refine: Annotated[
        int | None, typer.Option(help="Add a row: the svr models refined by K second-order "
                                      "steps (eqs. 5-6), beside the config's K.")
    ] = None,
    force: ForceOpt = False,
    json_out: JsonOpt = False,
) -> None:
    """Cross-validate the model against the baselines of Section 4 (Tables 1, 3, 4, 5)."""
    from ..data.calibration import GrossError, load_calibration
    from ..evaluation.cv import run_cv
    from ..evaluation.cv_results import cv_text, save_cv_results
    from ..evaluation.heldout import parse_folds
    from ..evaluation.tune import grid_option
    from ..reporting.console import cv_renderables
    from ..reporting.tune_table import tune_table

    with user_errors(flags={"tare": "--task-tare"}):  # cv zeroes the task log only
        settings = load_config(config)
        if (task is None) != (task_forces is None):
            raise InputError("--task and --task-forces go together: the log and its true forces")
        if task_tare is not None and task is None:
            raise InputError("--task-tare needs --task")
        if workers is not None and workers < 1:
            raise InputError(f"--workers {workers}: needs at least 1")
        grid = grid_option(tune, tune_grid)
        if output is not None:
            check_output(output, force=force)
        cs = load_calibration(calib, settings)
        if output is not None:
            refuse_overwriting_input(output, [*_read(cs), *_given(config, task, task_forces)])
        with progress_bar("training", MofNCompleteColumn()) as progress:
            doc = run_cv(
                cs, settings, folds=parse_folds(folds) if folds is not None else None,
                task=(task, task_forces) if task is not None else None, task_tare=task_tare,
                gross_error=GrossError.parse(gross_error, settings.layout) if gross_error else None,
                max_gamma=max_gamma, workers=workers, repeats=repeats, protocol=protocol,
                tune=tune, tune_grid=grid, refine=refine,
                progress=progress,
            )
        if output is not None:
            save_cv_results(doc, output, force=force)
    if json_out:
        sys.stdout.write(cv_text(doc))
    else:
        if "tune" in doc:
            console.print(tune_table(doc["tune"], settings.load_unit, settings.output_unit))
        for r in cv_renderables(doc):
            console.print(r)
        if output is not None:
            console.print(f"cv document written to {printable(output)}", highlight=False)
            console.print(
                f"calibration report: fsdecouple report MODEL --cv {printable(output)} "
                f"--calib {printable(calib)} -o report.html", highlight=False,
            )
    warn(doc["warnings"])
    if doc["gate"] is not None and not doc["gate"]["passed"]:
        raise typer.Exit(1)


@app.command()
def validate(
    model_file: Annotated[Path, typer.Argument(metavar="MODEL", help="Model file (JSON).")],
    set_path: Annotated[Path, typer.Argument(metavar="SET", help="Independent set, calibration format.")],
    config: ModelConfigOpt = None,
    output: Annotated[Path | None, output_file("Write validation.json.")] = None,
    max_gamma: Annotated[float | None, typer.Option(
        help="Exit 1 if the interference error (eq. 12) on calibrated points exceeds this fraction.")] = None,
    calib: Annotated[Path | None, typer.Option(
        "--calib", help="The model's calibration (directory or CSV), to fit the least-squares "
                        "matrix on when the model file holds none (fitted before it was kept).")] = None,
    force: ForceOpt = False, json_out: JsonOpt = False,
) -> None:
    """Score a model on an independent single-axis set: the model, the least-squares matrix
    and initial side by side, gamma and force errors per axis."""
    from ..evaluation.validate import validate as validate_set
    from ..reporting.validate_table import validation_renderables

    with user_errors():
        doc = validate_set(model_file, set_path, load_config(config) if config else None,
                           max_gamma=max_gamma, output=output, force=force, inputs=_given(config),
                           calib=calib)
    for to_stderr, r in validation_renderables(doc, output, as_json=json_out):
        (err_console if to_stderr else console).print(r, soft_wrap=True)
    raise typer.Exit(0 if doc["gate"] is None or doc["gate"]["passed"] else 1)


# names that are files, not the directory --png wants
FILE_SUFFIXES = {".html", ".htm", ".png", ".svg", ".pdf", ".json", ".csv", ".txt", ".md"}


@app.command()
def report(
    model_file: Annotated[Path, typer.Argument(help="Model file (JSON).")],
    output: Annotated[Path, output_file("HTML report to write.")],
    cv: Annotated[
        Path | None, typer.Option("--cv", help="cv.json of `fsdecouple cv`: Tables 1, 3, 5, residuals.")
    ] = None,
    calib: Annotated[
        Path | None, typer.Option("--calib", help="Calibration directory or CSV, to plot its points.")
    ] = None,
    png: Annotated[
        Path | None, typer.Option("--png", help="Also write each figure as a PNG into this directory.")
    ] = None,
    certificate: Annotated[
        Path | None, typer.Option("--certificate", help="The certificate (.html or .pdf) the "
                                  "report links to, from `fsdecouple certificate`.")
    ] = None,
    force: ForceOpt = False,
) -> None:
    """Write a self-contained HTML calibration report (figures, gamma tables, checks)."""
    from ..data.calibration import load_calibration
    from ..evaluation.cv_results import load_cv_results
    from ..evaluation.validate import refuse_meaningless
    from ..reporting.report import build_report, check_cv_fits, plots_other_files

    with user_errors():
        model = load_model(model_file)
        cv_doc = load_cv_results(cv) if cv is not None else None
        if cv_doc is not None:
            check_cv_fits(model, cv_doc, printable(cv))  # before any figure is drawn
        cs = load_calibration(calib, model.settings) if calib is not None else None
        if cs is not None:
            refuse_meaningless(cs, model)  # a 1e308 cell: no axis of a figure can hold it
        targets = [output]
        if png is not None:
            if png.exists() and not png.is_dir():
                raise InputError(f"--png {png}: exists and is not a directory")
            if not png.exists() and png.suffix.lower() in FILE_SUFFIXES:
                raise InputError(f"--png {png}: looks like a file name; give a directory "
                                 "for the PNG figures")
        inputs = [model_file, *_given(cv), *(_read(cs) if cs is not None else [])]
        check_output(output, force=force)
        refuse_overwriting_input(output, inputs)
        link = None
        if certificate is not None:
            if certificate.suffix.lower() not in (".html", ".htm", ".pdf"):
                raise InputError(f"--certificate {printable(certificate)}: expected the .html or "
                                 "a .pdf certificate of `fsdecouple certificate`")
            if certificate.resolve() == output.resolve():
                raise InputError(f"--certificate {printable(certificate)}: is the report's own "
                                 "file (-o); give the certificate's")
            if not certificate.is_file():
                warn([f"--certificate {printable(certificate)}: no such file yet; the report "
                      "links to it"])
            # relative to the report's directory, so the two files move together
            link = Path(os.path.relpath(certificate.resolve(), output.resolve().parent)).as_posix()
        result = build_report(model, cv_doc, cs, certificate=link)
        if cs is not None and plots_other_files(model, cs):
            warn([f"--calib {printable(calib)}: not exactly the files the model was fitted on "
                  "(digests differ): the points may not match the curves"])
        if png is not None:
            targets += [png / f"{name}.png" for name in result.figures]
        for t in targets:
            if t.parent.is_dir():
                check_output(t, force=force)
            refuse_overwriting_input(t, inputs)
        # the report and its PNGs (and the --png directory) appear together or not at all
        with atomic_files(force=force) as group:
            with group.open(output) as fh:
                fh.write(result.html)
            for name, data in result.figures.items() if png is not None else ():
                with group.open(png / f"{name}.png", "wb") as fh:
                    fh.write(data)
    console.print(f"report written to {printable(output)} ({len(result.figures)} figures)", highlight=False)
    if png is not None:
        console.print(f"figures written to {printable(png)}/: "
                      + ", ".join(f"{n}.png" for n in result.figures), highlight=False)
