"""Commands for many sensors and calibrations over time: compare, fit-many."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .app import ForceOpt, JsonOpt, app, console, print_json, progress_bar, say, show, user_errors, warn

MaxDriftOpt = Annotated[
    float | None, typer.Option("--max-drift", help="Exit 1 if any change exceeds P [%], e.g. 0.5.")
]


@app.command()
def compare(
    old_model: Annotated[Path, typer.Argument(help="The earlier model file (JSON).")],
    new_model: Annotated[Path, typer.Argument(help="The new model file of the same sensor.")],
    max_drift: MaxDriftOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Drift between two calibrations of one sensor: slopes, chi and forces, in % F.S."""
    from ..fleet.drift import compare as compare_models
    from ..reporting.fleet_tables import drift_line, drift_table

    with user_errors():
        doc = compare_models(old_model, new_model, max_drift=max_drift)
    if json_out:
        print_json(doc)
    else:
        console.print(drift_table(doc))
    line = drift_line(doc)
    if doc["passed"] is False:
        say([line], "gate failed")
        raise typer.Exit(1)
    if line and not json_out:
        console.print(line)


@app.command("fit-many")
def fit_many(
    sensors_dir: Annotated[Path, typer.Argument(
        help="One subdirectory per sensor: sensor.yaml and its calibration CSVs "
             "(or a calibration/ folder).")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Directory for <sensor>.json models.")],
    max_gamma: Annotated[float | None, typer.Option(
        help="Exit 1 if a sensor's held-out worst interference error (eq. 12) "
             "exceeds this fraction, e.g. 0.016.")] = None,
    baseline: Annotated[Path | None, typer.Option(
        help="Directory of earlier <sensor>.json models: report each sensor's drift.")] = None,
    max_drift: MaxDriftOpt = None,
    method: Annotated[str | None, typer.Option(
        help="svr, linear or auto, as fit --method (default: the config's method, else svr).")
    ] = None,
    workers: Annotated[int | None, typer.Option(help="Sensors fitted at once (processes); "
                                                     "default: the cores.")] = None,
    force: ForceOpt = False,
    json_out: JsonOpt = False,
) -> None:
    """Fit every sensor of a directory in parallel; one model file each, one summary."""
    from rich.progress import MofNCompleteColumn

    from ..fleet.sensors import fit_many as fit_all
    from ..reporting.fleet_tables import fleet_errors, fleet_gate_lines, fleet_table, fleet_warnings

    with user_errors(), progress_bar("fitting", MofNCompleteColumn()) as progress:
        result = fit_all(sensors_dir, output, method=method, max_gamma=max_gamma, baseline=baseline,
                         max_drift=max_drift, force=force, workers=workers, progress=progress)
    doc = result.to_dict()
    show(doc, fleet_table, json_out)
    warn(fleet_warnings(doc))
    say(fleet_errors(doc))
    say(fleet_gate_lines(doc), "gate failed")
    if doc["failed"]:
        raise typer.Exit(2)
    if doc["gate_failed"]:
        raise typer.Exit(1)
