"""The ``fsdecouple`` command: a thin Typer shell over the Python API.

Each command parses its arguments, calls one library function, renders the
result and picks the exit code: 0 done, 1 a gate failed (``--max-gamma``),
2 bad input (one line on stderr, no traceback, no output file).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.progress import (
    BarColumn,
    DownloadColumn,
    MofNCompleteColumn,
    Progress,
    TimeRemainingColumn,
)

from . import __version__
from .config import load_config
from .console import apply_lines, apply_warnings, fit_tables, ingest_tables
from .errors import FsdecoupleError, InputError
from .iotools.files import atomic_write, check_output, refuse_overwriting_input
from .modelfile import load_model, save_model

# Each command imports what only it needs (pandas, libsvm, scipy, matplotlib),
# so that `apply` and `show` start in a fraction of a second.

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
    from .calibration import GrossError
    from .simulate import simulate as simulate_sensor

    with user_errors():
        ge = GrossError.parse(gross_error) if gross_error else None
        files = simulate_sensor(out_dir, seed=seed, gross_error=ge, force=force)
    console.print(f"wrote {len(files)} files under {out_dir}")


@app.command()
def init(
    data_file: Annotated[Path, typer.Argument(help="A calibration CSV to guess the config from.")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Config file to write (YAML).")],
    force: ForceOpt = False,
    json_out: JsonOpt = False,
) -> None:
    """Start a config: guess columns, units, full scale and scaling from a calibration file."""
    from .guess import guess_renderables, init_config

    try:  # not user_errors(): the message quotes the header, and "[/]" is not rich markup
        guess = init_config(data_file, output, force=force)
    except FsdecoupleError as err:
        err_console.print(f"error: {err}", style="red", markup=False, highlight=False,
                          soft_wrap=True)
        raise typer.Exit(2) from None
    if json_out:
        return print_json(guess.to_dict())
    for r in guess_renderables(guess):
        console.print(r, soft_wrap=True)


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
    from .calibration import ingest_summary, load_calibration

    with user_errors():
        settings = load_config(config)
        if output is not None:
            check_output(output, force=force)
        cs = load_calibration(calib, settings)
        if output is not None:
            refuse_overwriting_input(output, [*_read(cs), *_given(config)])
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
    from .calibration import load_calibration
    from .fit import fit as fit_model

    with user_errors():
        settings = load_config(
            config, C=C, epsilon=epsilon, gamma=gamma, delta2=delta2, tolerance=tolerance,
            scaling=scaling,
        )
        check_output(output, force=force)
        cs = load_calibration(calib, settings)
        refuse_overwriting_input(output, [*_read(cs), *_given(config)])
        model = fit_model(cs, settings)
        save_model(model, output, force=force)
    if json_out:
        print_json({"model": str(output), **model.report.to_dict()})
    else:
        for t in fit_tables(model):
            console.print(t)
        console.print(f"model written to {output}")
        console.print(f"calibration report: fsdecouple report {output} -o report.html", highlight=False)
    warn(model.warnings)
    if max_gamma is not None:
        worst = max(model.report.gamma_after.values())
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


@app.command()
def report(
    model_file: Annotated[Path, typer.Argument(help="Model file (JSON).")],
    output: Annotated[Path, typer.Option("--output", "-o", help="HTML report to write.")],
    cv: Annotated[
        Path | None, typer.Option("--cv", help="cv.json of `fsdecouple cv`: Tables 1, 3, 5, residuals.")
    ] = None,
    calib: Annotated[
        Path | None, typer.Option("--calib", help="Calibration directory or CSV, to plot its points.")
    ] = None,
    png: Annotated[
        Path | None, typer.Option("--png", help="Also write each figure as a PNG into this directory.")
    ] = None,
    force: ForceOpt = False,
) -> None:
    """Write a self-contained HTML calibration report (figures, gamma tables, checks)."""
    from .calibration import load_calibration
    from .cv_doc import load_cv_results
    from .report import build_report

    with user_errors():
        model = load_model(model_file)
        cv_doc = load_cv_results(cv) if cv is not None else None
        cs = load_calibration(calib, model.settings) if calib is not None else None
        targets = [output]
        if png is not None:
            if png.exists() and not png.is_dir():
                raise InputError(f"--png {png}: exists and is not a directory")
            png.mkdir(parents=True, exist_ok=True)
        inputs = [model_file, *_given(cv), *(_read(cs) if cs is not None else [])]
        check_output(output, force=force)
        refuse_overwriting_input(output, inputs)
        result = build_report(model, cv_doc, cs)
        if png is not None:
            targets += [png / f"{name}.png" for name in result.figures]
        for t in targets:
            check_output(t, force=force)
            refuse_overwriting_input(t, inputs)
        with atomic_write(output, force=True) as fh:
            fh.write(result.html)
        for name, data in result.figures.items():
            if png is not None:
                with atomic_write(png / f"{name}.png", "wb", force=True) as fh:
                    fh.write(data)
    console.print(f"report written to {output} ({len(result.figures)} figures)", highlight=False)
    if png is not None:
        console.print(f"figures written to {png}/: " + ", ".join(f"{n}.png" for n in result.figures),
                      highlight=False)


def _read(calib) -> list[Path]:
    """The files a calibration set was read from."""
    return [Path(f) for f, _ in calib.files]


def _given(*paths):
    return [p for p in paths if p is not None]


def _parse_zero(text: str) -> tuple[float, float, float]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
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
    from .apply import apply_file
    from .iotools.logs import is_parquet

    with user_errors():
        model = load_model(model_file)
        settings = load_config(config) if config is not None else None
        offsets = _parse_zero(zero) if zero is not None else None
        check_output(output, force=force)
        refuse_overwriting_input(output, [model_file, *_given(config)])
        # apply counts progress in bytes of a CSV log, in rows of a Parquet one
        done = MofNCompleteColumn() if is_parquet(voltages) else DownloadColumn()
        with _bar(done, TimeRemainingColumn()) as bar:
            task = bar.add_task("decoupling", total=None)
            summary = apply_file(
                model, voltages, output, settings=settings, tare=tare, zero=offsets,
                force=force, round_trip=round_trip,
                progress=lambda done, total: bar.update(task, completed=done, total=total),
            )
    for line in apply_lines(summary, output):
        console.print(line, highlight=False)
    warn(apply_warnings(summary))


def _bar(*columns) -> Progress:
    """A progress bar on stderr, drawn on a terminal only (never with CI set), erased when done."""
    return Progress(
        "[progress.description]{task.description}", BarColumn(), *columns, console=err_console,
        disable=not interactive(), transient=True,
    )


@app.command()
def cv(
    calib: Annotated[Path, typer.Argument(help="Calibration directory or CSV.")],
    config: ConfigOpt = None,
    folds: Annotated[
        str | None,
        typer.Option(help='Held-out repetitions per round, e.g. "1,2;3,4;5,6" (the default).'),
    ] = None,
    output: Annotated[
        Path | None, typer.Option("--output", "-o", help="Write the cv.json document.")
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
        typer.Option(help="Move one training point: AXIS:REP:POINT:OFFSET[V], e.g. x:1:5:0.2"),
    ] = None,
    max_gamma: Annotated[
        float | None,
        typer.Option(help="Exit 1 if any svr gamma on held-out data exceeds this fraction."),
    ] = None,
    workers: Annotated[
        int | None, typer.Option(help="Training threads (default: cores; 1: sequential).")
    ] = None,
    repeats: Annotated[int, typer.Option(help="Sequential timing passes (Table 4).")] = 1,
    force: ForceOpt = False,
    json_out: JsonOpt = False,
) -> None:
    """Cross-validate the model against the baselines of Section 4 (Tables 1, 3, 4, 5)."""
    from .calibration import GrossError, load_calibration
    from .console import cv_renderables
    from .cv import parse_folds, run_cv

    with user_errors():
        settings = load_config(config)
        if (task is None) != (task_forces is None):
            raise InputError("--task and --task-forces go together: the log and its true forces")
        if task_tare is not None and task is None:
            raise InputError("--task-tare needs --task")
        if workers is not None and workers < 1:
            raise InputError(f"--workers {workers}: needs at least 1")
        if output is not None:
            check_output(output, force=force)
        cs = load_calibration(calib, settings)
        if output is not None:
            refuse_overwriting_input(output, [*_read(cs), *_given(config, task, task_forces)])
        with _bar(MofNCompleteColumn()) as bar:
            job = bar.add_task("training", total=None)
            doc = run_cv(
                cs, settings, folds=parse_folds(folds) if folds is not None else None,
                task=(task, task_forces) if task is not None else None, task_tare=task_tare,
                gross_error=GrossError.parse(gross_error) if gross_error else None,
                max_gamma=max_gamma, workers=workers, repeats=repeats,
                progress=lambda done, total: bar.update(job, completed=done, total=total),
            )
        text = json.dumps(doc, indent=1, sort_keys=True, allow_nan=False)
        if output is not None:
            with atomic_write(output, force=force) as fh:
                fh.write(text + "\n")
    if json_out:
        sys.stdout.write(text + "\n")
    else:
        for r in cv_renderables(doc):
            console.print(r)
        if output is not None:
            console.print(f"cv document written to {output}", highlight=False)
            console.print(
                f"calibration report: fsdecouple report MODEL --cv {output} --calib {calib} "
                "-o report.html", highlight=False,
            )
    warn(doc["warnings"])
    if doc["gate"] is not None and not doc["gate"]["passed"]:
        raise typer.Exit(1)


def _terminate(signum, frame) -> None:
    # SIGTERM (kill, CI timeouts) unwinds like Ctrl-C, so temporary files are removed
    raise SystemExit(128 + signum)


def main() -> None:
    signal.signal(signal.SIGTERM, _terminate)
    try:
        code = app(standalone_mode=False)
    except typer.Abort:
        err_console.print("[red]error:[/red] aborted", highlight=False)
        code = 1
    except Exception as err:
        # Click's usage errors (a missing argument, `--tare abc`, an unknown
        # command) get one line like every other bad input, not a framed box
        if not (hasattr(err, "format_message") and hasattr(err, "exit_code")):
            raise
        ctx = getattr(err, "ctx", None)
        command = ctx.command_path if ctx is not None else "fsdecouple"
        message = " ".join(err.format_message().split())
        if message:  # none when the help was printed for a bare `fsdecouple`
            err_console.print(f"[red]error:[/red] {command}: {message} (see '{command} --help')",
                              highlight=False, soft_wrap=True)
        code = err.exit_code
    sys.exit(code if isinstance(code, int) else 0)
