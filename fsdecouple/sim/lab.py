"""A lab technician's calibration spreadsheet, as simulated data are written in it.

A small 3-axis load cell is calibrated with weights: loads in gram-force, outputs
as raw 24-bit ADC counts, one repetition, each sweep one zero row followed by its
loads.  The sheet is exported as it is kept: after the data come two spacer
columns with empty headers and a side table of the protocol (orientation, nominal
load per axis, notes) that runs further down than the data.  There is no ``axis``
column: sweeps are told apart by their zero rows.  A ``repetition`` column is
written only when there is more than one repetition.
"""

from __future__ import annotations

import csv
from pathlib import Path

import pandas as pd

from ..axes import AXES, FORCE_COLUMNS, VOLTAGE_COLUMNS
from ..files.outputs import atomic_files, atomic_write

LOAD_UNIT = "gf"
LAB_LOAD_COLUMNS = tuple(f"F{a} [{LOAD_UNIT}]" for a in AXES)
LAB_OUTPUT_COLUMNS = tuple(f"ch{i}" for i in range(len(AXES)))
SPACER_COLUMNS = 2  # empty headers between the data and the side table
SIDE_COLUMNS = ("orientation", *(f"load on {a}" for a in AXES))
# the bottom of the side table: text where the loads are, numbers as text
SIDE_NOTES = (
    ("notes", "", "", ""),
    ("ADC", "24-bit, gain 128", "", ""),
    ("excitation", "5 V", "", ""),
    ("weights", "class M1", "hanger included", ""),
    ("room temperature", "21.5 C", "", ""),
)


def _load_text(v: float) -> str:
    """Loads as a technician types them: ``250``, ``333.333``."""
    return f"{v:.3f}".rstrip("0").rstrip(".")


def _side_table(table: pd.DataFrame) -> list[tuple[str, ...]]:
    """One row per weight set of the first repetition's sweeps, then the notes.

    With one repetition this is always longer than the data (3 K rows + notes
    against 3 (K + 1) data rows), so its last rows have no data beside them.
    """
    first = table[table["repetition"] == table["repetition"].iloc[0]]
    rows = []
    for a, axis in enumerate(AXES):
        loads = first.loc[first["axis"] == axis, FORCE_COLUMNS[a]]
        for load in loads[loads != 0]:
            on = ["0"] * len(AXES)
            on[a] = _load_text(load)
            rows.append((f"{axis.upper()}+ up", *on))
    return [*rows, *SIDE_NOTES]


def lab_rows(table: pd.DataFrame) -> list[list[str]]:
    """The spreadsheet, header first, from a long table of one simulated calibration.

    ``table`` has ``repetition, axis, fx, fy, fz, ux, uy, uz`` with loads [gf] and
    outputs [counts]; outputs are rounded to whole counts here.
    """
    several = table["repetition"].nunique() > 1
    data_header = [*(["repetition"] if several else []), *LAB_LOAD_COLUMNS, *LAB_OUTPUT_COLUMNS]
    spacer = [""] * SPACER_COLUMNS
    data = []
    for rec in table.itertuples(index=False):
        row = rec._asdict()
        data.append([
            *([str(row["repetition"])] if several else []),
            *(_load_text(row[c]) for c in FORCE_COLUMNS),
            *(str(int(round(row[c]))) for c in VOLTAGE_COLUMNS),
        ])
    side = _side_table(table)
    rows = [[*data_header, *spacer, *SIDE_COLUMNS]]
    for i in range(max(len(data), len(side))):
        d = data[i] if i < len(data) else [""] * len(data_header)
        s = list(side[i]) if i < len(side) else [""] * len(SIDE_COLUMNS)
        rows.append([*d, *spacer, *s])
    return rows


def write_lab_csv(table: pd.DataFrame, path: Path, *, force: bool,
                  group: atomic_files | None = None) -> None:
    """Write ``table`` as a lab spreadsheet export (comma CSV, ``\\n`` line ends).

    Given an :class:`~fsdecouple.files.outputs.atomic_files` ``group``, the file
    is placed with the group's other outputs, together or not at all.
    """
    with (group.open(path) if group is not None else atomic_write(path, force=force)) as fh:
        csv.writer(fh, lineterminator="\n").writerows(lab_rows(table))
