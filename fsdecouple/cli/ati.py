"""ATI calibration files: ``import FILE.cal -o model.json`` (``export -o x.cal`` is in model.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..core.modelfile import save_model
from ..files.outputs import check_output, refuse_overwriting_input
from .app import ForceOpt, JsonOpt, app, console, output_file, print_json, user_errors, warn


@app.command("import")
def import_(
    cal_file: Annotated[Path, typer.Argument(help="ATI calibration file (.cal XML).")],
    output: Annotated[Path, output_file("Model file to write (JSON).")],
    index: Annotated[int, typer.Option(help="Which Calibration element, counted from 1 "
                                             "(ATIDAQ's index).")] = 1,
    config: Annotated[Path | None, typer.Option(
        "--config", "-c", help="YAML holding frame: only (the tool transform, docs/six-axis.md); "
                               "everything else comes from the .cal file.")] = None,
    force: ForceOpt = False,
    json_out: JsonOpt = False,
) -> None:
    """Import an ATI calibration file as a linear model (decoupled as ATIDAQ does)."""
    from ..data.ati_model import import_cal, read_frame_config, summary

    with user_errors():
        check_output(output, force=force)
        refuse_overwriting_input(output, [cal_file, *([config] if config else [])])
        frame = read_frame_config(config) if config is not None else None
        model = import_cal(cal_file, index, frame, str(config))
        save_model(model, output, force=force)
    doc = summary(model, output)
    if json_out:
        print_json({k: v for k, v in doc.items() if k != "lines"})
        return
    for line in doc["lines"]:
        console.print(line, highlight=False, soft_wrap=True)
    warn(model.warnings)
