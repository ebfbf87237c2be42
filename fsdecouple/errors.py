"""The one exception family that the command line turns into a single red line.

Library code raises these for bad input or configuration; anything else is a bug
and keeps its traceback.
"""

from __future__ import annotations

from pathlib import Path


class FsdecoupleError(Exception):
    """Bad input or configuration; shown to the user as one line, no traceback."""


class InputError(FsdecoupleError):
    """A data file (calibration set, voltage log) cannot be used as it is."""


class ConfigError(FsdecoupleError):
    """The YAML configuration or a command-line setting is invalid."""


class ModelFileError(FsdecoupleError):
    """A model file is not a usable fsdecouple model."""


def where(file: str | Path | None, row: int | None = None, column: str | None = None) -> str:
    """Format a location as ``file, row 17, column 'uy'`` for error messages.

    Rows are counted as a spreadsheet shows them: the header is row 1.
    """
    parts = []
    if file is not None:
        parts.append(str(file))
    if row is not None:
        parts.append(f"row {row}")
    if column is not None:
        parts.append(f"column '{column}'")
    return ", ".join(parts)
