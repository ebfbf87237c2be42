"""The command that decouples logs: apply."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.progress import DownloadColumn, MofNCompleteColumn, TimeRemainingColumn

from ..config import load_config
from ..core.modelfile import load_model
from ..errors import InputError
from ..files.outputs import check_output, refuse_overwriting_input
from ..reporting.console import apply_lines, apply_warnings
from .app import (
    ForceOpt,
    JsonOpt,
    ModelConfigOpt,
    _given,
    _parse_zero,
    app,
    ascii_digits,
    console,
    print_json,
    progress_bar,
    say,
    show,
    user_errors,
    warn,
)


@app.command()
def apply(
    model_file: Annotated[Path, typer.Argument(help="Model file (JSON).")],
    voltages: Annotated[
        list[Path], typer.Argument(help="Voltage log with ux, uy, uz: CSV, or Parquet (.parquet); "
                                        "or several logs, globs or directories (-o OUT_DIR/).")
    ],
    output: Annotated[  # text, not a Path, which would drop the trailing / of OUT_DIR/
        str, typer.Option("--output", "-o", metavar="OUTPUT",
                          help="Forces file to write: CSV, or Parquet (.parquet); for several "
                               "logs, a directory (a trailing / makes it one).")
    ],
    config: ModelConfigOpt = None,
    tare: Annotated[
        int | None, typer.Option(help="Subtract the mean voltages of the first N rows.")
    ] = None,
    zero: Annotated[
        str | None, typer.Option(help="Subtract offsets ux,uy,uz (the model's output unit).",
                                 callback=ascii_digits)
    ] = None,
    unit: Annotated[
        str | None,
        typer.Option(help="Write forces in this load unit (N, kN, gf, kgf, lbf, klbf); "
                          "default: the calibration's."),
    ] = None,
    refine: Annotated[
        int | None, typer.Option(help="Second-order refinement steps K for this run "
                                      "(default: the model's).")
    ] = None,
    round_trip: Annotated[
        bool, typer.Option("--round-trip", help="CSV: write forces as round-trip exact text.")
    ] = False,
    engine: Annotated[str, typer.Option(help="Many logs: local (threads here) or dask.")] = "local",
    scheduler: Annotated[
        str | None, typer.Option(help="Many logs, --engine dask: the address of a running Dask "
                                      "scheduler; default: a LocalCluster on this machine.")
    ] = None,
    workers: Annotated[
        int | None, typer.Option(help="Many logs: threads, as many logs at once (local), or the "
                                      "LocalCluster's worker processes (dask); default: the cores.")
    ] = None,
    interval: Annotated[
        float | None, typer.Option(help="Add <component>_lo and _hi columns holding the true force "
                                        "with this probability (0 < P < 1), e.g. 0.95.")
    ] = None,
    temperature: Annotated[
        float | None, typer.Option(help="A model with temperature terms, a log without the "
                                        "temperature column: this reading for every row (an "
                                        "ATI thermistor's volts; for a fitted model, in the "
                                        "config's units: temperature, degC by default).")
    ] = None,
    force: ForceOpt = False,
    json_out: JsonOpt = False,
) -> None:
    """Decouple logged voltages into forces fx, fy, fz (a model's components) by eq. (11)."""
    from ..logs.apply import apply_file
    from ..logs.many import is_batch
    from ..logs.reader import is_parquet

    if is_batch(voltages, output):
        if temperature is not None:
            with user_errors():
                raise InputError("--temperature: for one log (not yet for many)")
        return _apply_many(model_file, voltages, Path(output), config, tare, zero, unit, refine,
                           round_trip, engine, scheduler, workers, force, json_out, interval)
    with user_errors():
        if engine != "local" or scheduler is not None or workers is not None:
            raise InputError("--engine, --scheduler and --workers are for many logs: "
                             "give the output directory with a trailing / (-o OUT_DIR/)")
        voltages, output = voltages[0], Path(output)
        model = load_model(model_file)
        if refine is not None:
            model = model.refined(refine)
        settings = load_config(config) if config is not None else None
        offsets = _parse_zero(zero) if zero is not None else None
        check_output(output, force=force)
        refuse_overwriting_input(output, [model_file, *_given(config)])
        # apply counts progress in bytes of a CSV log, in rows of a Parquet one
        done = MofNCompleteColumn() if is_parquet(voltages) else DownloadColumn()
        with progress_bar("decoupling", done, TimeRemainingColumn()) as progress:
            summary = apply_file(
                model, voltages, output, settings=settings, tare=tare, zero=offsets,
                unit=unit, force=force, round_trip=round_trip, progress=progress,
                interval=interval, temperature=temperature,
            )
    if json_out:
        print_json({"output": str(output), **summary.to_dict()})
        return
    for line in apply_lines(summary, output):
        console.print(line, highlight=False, markup=False)  # '[mV]' is no markup
    warn(apply_warnings(summary))


def _apply_many(model_file, inputs, output, config, tare, zero, unit, refine, round_trip, engine,
                scheduler, workers, force, json_out, interval) -> None:
    from rich.progress import MofNCompleteColumn

    from ..logs.many import apply_many
    from ..reporting.fleet_tables import apply_many_errors, apply_many_table

    with user_errors():
        settings = load_config(config) if config is not None else None
        offsets = _parse_zero(zero) if zero is not None else None
        with progress_bar("decoupling logs", MofNCompleteColumn(), TimeRemainingColumn()) as progress:
            result = apply_many(
                model_file, inputs, output, engine=engine, scheduler=scheduler, workers=workers,
                settings=settings, config=config, tare=tare, zero=offsets, unit=unit, refine=refine,
                round_trip=round_trip, force=force, interval=interval, progress=progress)
    doc = result.to_dict()
    show(doc, apply_many_table, json_out)
    warn(doc["warnings"])
    say(apply_many_errors(doc))
    if doc["failed"]:
        raise typer.Exit(2)
