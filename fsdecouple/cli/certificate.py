"""The command that writes a calibration certificate: certificate."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer

from ..config import load_config
from ..core.modelfile import load_model
from ..errors import InputError, printable
from ..files.outputs import check_output, refuse_overwriting_input
from .app import (
    ForceOpt,
    JsonOpt,
    ModelConfigOpt,
    _given,
    _read,
    app,
    console,
    output_file,
    print_json,
    user_errors,
    warn,
)


@app.command()
def certificate(
    model_file: Annotated[Path, typer.Argument(help="Model file (JSON) fitted on CALIB.")],
    calib: Annotated[Path, typer.Argument(help="The calibration directory or CSV it was fitted on.")],
    config: ModelConfigOpt = None,
    output: Annotated[
        Path | None, output_file("Certificate to write: .html (prints on A4) or .pdf (A4).")
    ] = None,
    drift: Annotated[
        Path | None, typer.Option("--drift", help="compare --json output of this sensor's last "
                                  "two calibrations: the budget's drift term.")
    ] = None,
    force: ForceOpt = False,
    json_out: JsonOpt = False,
) -> None:
    """ISO 376 figures (b, b', f_c, f_0, v, c), class and uncertainty budget (U, k = 2) per step."""
    from ..data.calibration import excluded_lines, load_calibration
    from ..evaluation.certificate_doc import certificate as build
    from ..evaluation.certificate_doc import check_matches, read_drift
    from ..reporting.certificate_file import check_certificate_path, write_certificate
    from ..reporting.certificate_html import certificate_tables

    with user_errors():
        model = load_model(model_file)
        settings = load_config(config) if config is not None else None
        if output is not None:
            check_certificate_path(output)
            check_output(output, force=force)
        changes = read_drift(drift) if drift is not None else None
        read_as = settings or model.settings
        if model.provenance.get("files"):
            # the set is matched file by file with the model's (check_matches): a missing
            # repetition is named there, not counted against min_repetitions first
            read_as = replace(read_as, min_repetitions=1)
        left_out = excluded_lines(model.provenance.get("excluded"))
        try:
            cs = load_calibration(calib, read_as, exclude=left_out)  # as fit --exclude left it
        except InputError as err:
            if not left_out or getattr(err, "argument", None) != "exclude":
                raise
            # a line the model's fit left out is not in this set: it is not the set the
            # model was fitted on, which check_matches says by file, as for any model
            check_matches(model, load_calibration(calib, read_as), str(model_file), settings)
            raise InputError(f"{calib}: does not match the model file {model_file}: "
                             f"{printable(err)}") from None
        doc = build(model, cs, source=str(model_file), settings=settings, drift=changes,
                    drift_name=str(drift))
        if output is not None:
            refuse_overwriting_input(output, [model_file, *_read(cs), *_given(config),
                                              *_given(drift)])
            write_certificate(doc, output, force=force)
    warn(doc["warnings"])
    if json_out:
        print_json(doc)
    else:
        for t in certificate_tables(doc):
            console.print(t)
        for n in doc["notes"]:
            console.print(f"note: {n}")
    if output is not None and not json_out:
        console.print(f"certificate written to {printable(output)}")
