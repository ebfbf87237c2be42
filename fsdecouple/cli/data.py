"""Commands that make and read calibration data: simulate, ingest."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..config import load_config
from ..errors import printable
from ..files.outputs import atomic_write, check_output, refuse_overwriting_input
from ..reporting.console import ingest_tables
from .app import (
    ConfigOpt,
    ForceOpt,
    JsonOpt,
    _given,
    _read,
    app,
    ascii_digits,
    console,
    output_file,
    print_json,
    user_errors,
    warn,
)


@app.command()
def simulate(
    out_dir: Annotated[Path, typer.Argument(help="Directory to write the data set into.")],
    seed: Annotated[int, typer.Option(help="Random seed (>= 0).")] = 0,
    gross_error: Annotated[
        str | None,
        typer.Option(help="Move one point: AXIS:REP:POINT:OFFSET (in the output unit), e.g. x:1:5:0.2",
                     callback=ascii_digits),
    ] = None,
    layout: Annotated[
        str,
        typer.Option(help="paper: the paper's sensor, grid and files; lab: a load cell [gf, "
                          "ADC counts] in a lab spreadsheet, calibration.csv + validation.csv."),
    ] = "paper",
    repetitions: Annotated[
        int | None, typer.Option(help="Repetitions (default: 6 for paper, 1 for lab).")
    ] = None,
    levels: Annotated[
        int | None, typer.Option(help="Loads per sweep after its zero row: --layout lab (default 4) or "
                                 "--rig lever-arm|quadratic.")
    ] = None,
    coupling: Annotated[
        float | None, typer.Option(help="Peak of every coupling function, as a fraction of "
                                        "full-scale output (0 to 0.3; default: the sensor's own).")
    ] = None,
    hysteresis: Annotated[
        float | None, typer.Option(help="Sweep every axis out and back, with a sensor whose way "
                                        "down reads this fraction of full-scale output above the "
                                        "way up (0 to 0.05; paper layout only), in the task log "
                                        "too.")
    ] = None,
    components: Annotated[
        int | None, typer.Option(help="3: the paper's force sensor (the default); 6: a six-axis "
                                      "force/torque sensor (fx..mz, u1..u6) with its config "
                                      "sensor.yaml (--rig: always 6).")
    ] = None,
    rig: Annotated[
        str | None, typer.Option(help="lever-arm: a six-axis rig's calibration.csv whose moments "
                                      "come from a force on a lever arm (known_Fx.. headers); "
                                      "quadratic: the same rig, its readings bending with the "
                                      "squares of the loads (a few % F.S.); poses: 60 static "
                                      "poses of a known mass, eight gauges in 10-bit counts, "
                                      "pose01..pose60.csv (no unloaded pose).")
    ] = None,
    gauges: Annotated[
        int | None, typer.Option(help="--rig only: output channels, 6 to 64 (default 6: readings "
                                      "Fx..Mz; 8: gauges g1..g8, more outputs than components).")
    ] = None,
    temperature: Annotated[
        bool, typer.Option("--temperature", help="The paper's sensor drifting with temperature: "
                                                 "repetitions at 15, 25 and 35 degC (a temperature "
                                                 "column), a task log drifting through 10-40 degC "
                                                 "after a tare at 25 degC and its twin at 25 degC, "
                                                 "sensor.yaml and truth.json (docs/temperature.md).")
    ] = False,
    force: ForceOpt = False,
) -> None:
    """Write a simulated calibration set: the paper's (with a combined-load task log) or a lab's."""
    from ..axes import DEFAULT, Layout
    from ..data.calibration import GrossError
    from ..errors import InputError
    from ..sim.simulate import simulate as simulate_sensor
    from ..sim.six_axis import COMPONENTS, OUTPUTS, write_six_axis

    with user_errors():
        if temperature:
            from ..sim.simulate import check_count
            from ..sim.thermal import write_thermal

            given = [o for o, v in (("--rig", rig), ("--gauges", gauges), ("--levels", levels),
                                    ("--gross-error", gross_error), ("--coupling", coupling),
                                    ("--hysteresis", hysteresis)) if v is not None]
            given += [o for o, v, d in (("--layout", layout, "paper"), ("--components", components, 3))
                      if v not in (d, None)]
            if given:  # never ignored in silence
                raise InputError(f"--temperature: {', '.join(given)}: not with --temperature (the "
                                 "paper's sensor on its grid, drifting with temperature)")
            check_count(seed, "seed", 0)
            if repetitions is not None:
                check_count(repetitions, "repetitions", 3, 999)
            files = write_thermal(out_dir, seed=seed, repetitions=repetitions or 6, force=force)
            console.print(f"wrote {len(files)} files under {printable(out_dir)}")
            return
        if hysteresis is not None and (components == 6 or rig is not None):
            raise InputError("--hysteresis: only for the three-axis paper layout")
        if rig is not None:
            from ..sim.rig import LEVELS, write_rig

            given = [o for o, v in (("--repetitions", repetitions), ("--coupling", coupling),
                                    ("--gross-error", gross_error)) if v is not None]
            given += [o for o, v, d in (("--layout", layout, "paper"), ("--components", components, 6))
                      if v not in (d, None)]
            if given:  # never ignored in silence
                raise InputError(f"--rig: {', '.join(given)}: not with --rig (a rig file has its own "
                                 "layout: six components)")
            if rig == "poses":
                from ..sim.poses import write_poses

                if gauges is not None or levels is not None:
                    raise InputError("--rig poses: eight gauges and 60 poses; no --gauges or --levels")
                files = write_poses(out_dir, seed=seed, force=force)
                console.print(f"wrote {len(files)} files under {printable(out_dir)}")
                return
            files = write_rig(out_dir, seed=seed, gauges=6 if gauges is None else gauges,
                              levels=LEVELS if levels is None else levels, force=force, kind=rig)
            console.print(f"wrote {len(files)} files under {printable(out_dir)}")
            return
        if gauges is not None:
            raise InputError("--gauges: only with --rig (a rig's output channels)")
        components = 3 if components is None else components
        if components not in (3, 6):
            raise InputError(f"--components {components}: expected 3 or 6")
        named = Layout.named(COMPONENTS, OUTPUTS) if components == 6 else DEFAULT
        ge = GrossError.parse(gross_error, named) if gross_error else None
        if components == 6 and (layout != "paper" or levels is not None):
            raise InputError("--components 6: writes its own layout; no --layout lab or --levels")
        if components == 6:
            files = write_six_axis(out_dir, seed=seed, repetitions=repetitions or 6, force=force,
                                   coupling=coupling, gross_error=ge)
        else:
            files = simulate_sensor(out_dir, seed=seed, gross_error=ge, force=force,
                                    layout=layout, repetitions=repetitions, levels=levels,
                                    coupling=coupling, hysteresis=hysteresis)
    console.print(f"wrote {len(files)} files under {printable(out_dir)}")


@app.command()
def ingest(
    calib: Annotated[Path, typer.Argument(help="Calibration directory or CSV.")],
    config: ConfigOpt = None,
    output: Annotated[
        Path | None, output_file("Write the zero-corrected tidy CSV.")
    ] = None,
    force: ForceOpt = False,
    json_out: JsonOpt = False,
) -> None:
    """Validate and zero-correct a calibration set, and summarise it."""
    from ..data.calibration import ingest_summary, load_calibration

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
def init(
    data_file: Annotated[Path, typer.Argument(help="A calibration CSV to guess the config from, "
                                                   "or a directory of them (pose files).")],
    output: Annotated[Path, output_file("Config file to write (YAML).")],
    force: ForceOpt = False,
    json_out: JsonOpt = False,
) -> None:
    """Start a config: guess columns, units, full scale and scaling from a calibration file."""
    from ..data.init_config import init_config
    from ..reporting.console import guess_renderables

    with user_errors():
        guess = init_config(data_file, output, force=force)
    if json_out:
        return print_json(guess.to_dict())
    for r in guess_renderables(guess):
        console.print(r, soft_wrap=True)
