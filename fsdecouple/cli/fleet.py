"""Commands for many sensors and calibrations over time: compare, fit-many."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.text import Text

from .app import JsonOpt, app, console, err_console, print_json, user_errors

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
    from ..console_fleet import drift_line, drift_table
    from ..drift import compare as compare_models

    with user_errors():
        doc = compare_models(old_model, new_model, max_drift=max_drift)
    if json_out:
        print_json(doc)
    else:
        console.print(drift_table(doc))
    line = drift_line(doc)
    if doc["passed"] is False:
        err_console.print(Text("gate failed: ", "red") + Text(line), soft_wrap=True)
        raise typer.Exit(1)
    if line and not json_out:
        console.print(line)
