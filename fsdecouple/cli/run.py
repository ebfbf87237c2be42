"""The command that decouples logs: apply."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.progress import DownloadColumn, MofNCompleteColumn, TimeRemainingColumn

from ..config import load_config
from ..console import apply_lines, apply_warnings
from ..iotools.files import check_output, refuse_overwriting_input
from ..modelfile import load_model
from .app import (
    ConfigOpt,
    ForceOpt,
    _bar,
    _given,
    _parse_zero,
    app,
    console,
    user_errors,
    warn,
)


@app.command()
def apply(
    model_file: Annotated[Path, typer.Argument(help="Model file (JSON).")],
    voltages: Annotated[
        Path, typer.Argument(help="Voltage log with ux, uy, uz: CSV, or Parquet (.parquet).")
    ],
    output: Annotated[
        Path, typer.Option("--output", "-o", help="Forces file to write: CSV, or Parquet (.parquet).")
    ],
    config: ConfigOpt = None,
    tare: Annotated[
        int | None, typer.Option(help="Subtract the mean voltages of the first N rows.")
    ] = None,
    zero: Annotated[
        str | None, typer.Option(help="Subtract offsets ux,uy,uz (the model's output unit).")
    ] = None,
    unit: Annotated[
        str | None,
        typer.Option(help="Write forces in this load unit (N, kN, gf, kgf, lbf); "
                          "default: the calibration's."),
    ] = None,
    refine: Annotated[
        int | None, typer.Option(help="Second-order refinement steps K for this run "
                                      "(default: the model's).")
    ] = None,
    round_trip: Annotated[
        bool, typer.Option("--round-trip", help="CSV: write forces as round-trip exact text.")
    ] = False,
    force: ForceOpt = False,
) -> None:
    """Decouple logged voltages into forces fx, fy, fz (a model's components) by eq. (11)."""
    from ..apply import apply_file
    from ..iotools.logs import is_parquet

    with user_errors():
        model = load_model(model_file)
        if refine is not None:
            model = model.refined(refine)
        settings = load_config(config) if config is not None else None
        offsets = _parse_zero(zero, model.layout.outputs) if zero is not None else None
        check_output(output, force=force)
        refuse_overwriting_input(output, [model_file, *_given(config)])
        # apply counts progress in bytes of a CSV log, in rows of a Parquet one
        done = MofNCompleteColumn() if is_parquet(voltages) else DownloadColumn()
        with _bar(done, TimeRemainingColumn()) as bar:
            task = bar.add_task("decoupling", total=None)
            summary = apply_file(
                model, voltages, output, settings=settings, tare=tare, zero=offsets,
                unit=unit, force=force, round_trip=round_trip,
                progress=lambda done, total: bar.update(task, completed=done, total=total),
            )
    for line in apply_lines(summary, output):
        console.print(line, highlight=False, markup=False)  # '[mV]' is no markup
    warn(apply_warnings(summary))
