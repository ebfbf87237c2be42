"""The ``fsdecouple`` command: a thin Typer shell over the Python API.

Each command parses its arguments, calls one library function, renders the
result and picks the exit code: 0 done, 1 a gate failed (``--max-gamma``),
2 bad input (one line on stderr, no traceback, no output file).
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.progress import BarColumn, DownloadColumn, Progress, TimeRemainingColumn

from . import __version__
from .apply import apply_file
from .calibration import GrossError, load_calibration
from .config import load_config
from .errors import FsdecoupleError, InputError
from .io import atomic_write
from .model import fit as fit_model
from .model import load_model
from .report import apply_lines, apply_warnings, fit_tables, ingest_summary, ingest_tables
from .simulate import simulate as simulate_sensor

app = typer.Typer(
    add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
    help="Static decoupling of 3-axis force sensors: coupling error model + six eps-SVRs.",
)
console = Console()
err_console = Console(stderr=True)

ConfigOpt = Annotated[
    Path | None, typer.Option("--config", "-c", help="YAML config (default: the paper's sensor).")
]
ForceOpt = Annotated[bool, typer.Option("--force", help="Overwrite existing output files.")]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print a JSON document on stdout.")]


@contextlib.contextmanager
def user_errors():
    """Turn library errors into one red line on stderr and exit code 2."""
    try:
        yield
    except FsdecoupleError as err:
        err_console.print(f"[red]error:[/red] {err}", highlight=False, soft_wrap=True)
        raise typer.Exit(2) from None


def interactive() -> bool:
    return err_console.is_terminal and not os.environ.get("CI")


def warn(lines) -> None:
    for line in lines:
        err_console.print(f"[yellow]warning:[/yellow] {line}", highlight=False, soft_wrap=True)


def print_json(doc) -> None:
    sys.stdout.write(json.dumps(doc, indent=2, sort_keys=True, allow_nan=False) + "\n")


def version_callback(value: bool) -> None:
    if value:
        console.print(f"fsdecouple {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    version: Annotated[
        bool, typer.Option("--version", callback=version_callback, is_eager=True)
    ] = False,
) -> None:
    pass


@app.command()
def simulate(
    out_dir: Annotated[Path, typer.Argument(help="Directory to write the data set into.")],
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    gross_error: Annotated[
        str | None, typer.Option(help="Move one point: AXIS:REP:POINT:OFFSET[V], e.g. x:1:5:0.2")
    ] = None,
    force: ForceOpt = False,
) -> None:
    """Write a simulated six-repetition calibration set and a combined-load task log."""
    with user_errors():
        ge = GrossError.parse(gross_error) if gross_error else None
        files = simulate_sensor(out_dir, seed=seed, gross_error=ge, force=force)
    console.print(f"wrote {len(files)} files under {out_dir}")


@app.command()
def ingest(
    calib: Annotated[Path, typer.Argument(help="Calibration directory or CSV.")],
    config: ConfigOpt = None,
    output: Annotated[
        Path | None, typer.Option("--output", "-o", help="Write the zero-corrected tidy CSV.")
    ] = None,
    force: ForceOpt = False,
    json_out: JsonOpt = False,
) -> None:
    """Validate and zero-correct a calibration set, and summarise it."""
    with user_errors():
        settings = load_config(config)
        cs = load_calibration(calib, settings)
        summary = ingest_summary(cs, settings)
        if output is not None:
            with atomic_write(output, force=force) as fh:
                cs.points.to_csv(fh, index=False, lineterminator="\n")
    if json_out:
        print_json(summary)
    else:
        for r in ingest_tables(summary):
            console.print(r)
    warn(summary["warnings"])


@app.command()
def fit(
    calib: Annotated[Path, typer.Argument(help="Calibration directory or CSV.")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Model file to write (JSON).")],
    config: ConfigOpt = None,
    C: Annotated[float | None, typer.Option("--C", help="SVR regularisation C.")] = None,
    epsilon: Annotated[float | None, typer.Option(help="SVR epsilon [V].")] = None,
    gamma: Annotated[float | None, typer.Option(help="RBF gamma = 1/(2 delta^2).")] = None,
    delta2: Annotated[float | None, typer.Option(help="RBF delta^2.")] = None,
    tolerance: Annotated[float | None, typer.Option(help="libsvm stopping tolerance.")] = None,
    scaling: Annotated[str | None, typer.Option(help="Kernel input scaling: none|full_scale.")] = None,
    max_gamma: Annotated[
        float | None,
        typer.Option(help="Exit 1 if any gamma after decoupling exceeds this fraction."),
    ] = None,
    force: ForceOpt = False,
    json_out: JsonOpt = False,
) -> None:
    """Fit the coupling error model and write it as one JSON file."""
    with user_errors():
        settings = load_config(
            config, C=C, epsilon=epsilon, gamma=gamma, delta2=delta2, tolerance=tolerance,
            scaling=scaling,
        )
        if not force and output.exists():
            raise InputError(f"{output}: already exists; pass --force to overwrite it")
        model = fit_model(calib, settings)
        model.save(output, force=force)
    if json_out:
        print_json({"model": str(output), **model.report})
    else:
        for t in fit_tables(model):
            console.print(t)
        console.print(f"model written to {output}")
    warn(model.warnings)
    if max_gamma is not None:
        worst = max(model.report["gamma_after"].values())
        if worst > max_gamma:
            err_console.print(
                f"[red]gate failed:[/red] gamma after decoupling {100 * worst:.3f} % F.S. "
                f"exceeds --max-gamma {100 * max_gamma:.3f} %"
            )
            raise typer.Exit(1)


@app.command()
def show(model_file: Annotated[Path, typer.Argument(help="Model file (JSON).")]) -> None:
    """Print a model file's slopes, SVRs and fit report."""
    with user_errors():
        model = load_model(model_file)
    for t in fit_tables(model):
        console.print(t)
    warn(model.warnings)


def _parse_zero(text: str) -> tuple[float, float, float]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3:
        raise InputError(f"--zero {text!r}: expected three voltages ux,uy,uz, e.g. 0.01,-0.02,0")
    return values  # type: ignore[return-value]


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
    zero: Annotated[str | None, typer.Option(help="Subtract offsets ux,uy,uz [V].")] = None,
    round_trip: Annotated[
        bool, typer.Option("--round-trip", help="CSV: write forces as round-trip exact text.")
    ] = False,
    force: ForceOpt = False,
) -> None:
    """Decouple logged voltages into forces fx, fy, fz [N] by eq. (11)."""
    with user_errors():
        model = load_model(model_file)
        settings = load_config(config) if config is not None else None
        offsets = _parse_zero(zero) if zero is not None else None
        with Progress(
            "[progress.description]{task.description}", BarColumn(), DownloadColumn(),
            TimeRemainingColumn(), console=err_console, disable=not interactive(),
            transient=True,
        ) as bar:
            task = bar.add_task("decoupling", total=None)
            summary = apply_file(
                model, voltages, output, settings=settings, tare=tare, zero=offsets,
                force=force, round_trip=round_trip,
                progress=lambda done, total: bar.update(task, completed=done, total=total),
            )
    for line in apply_lines(summary, output):
        console.print(line, highlight=False)
    warn(apply_warnings(summary))


def main() -> None:
    app()
