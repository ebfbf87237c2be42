"""The one exception family that the command line turns into a single red line.

Library code raises these for bad input or configuration; anything else is a bug
and keeps its traceback.
"""

from __future__ import annotations

import unicodedata
from pathlib import Path


class FsdecoupleError(Exception):
    """Bad input or configuration; shown to the user as one line, no traceback.

    ``argument``: the Python name of the argument at fault (``tare``, ``exclude``), when
    the message is about one.  The message speaks of the data; the command line adds the
    flag the user typed (``cli.app.user_errors``), so the library never names a flag.
    ``remedy``: (argument, value) that would get past the error, when the message ends by
    suggesting it (``("exclude", "rep3.csv:17")``); the command line spells it as a flag.
    """

    def __init__(self, *args: object, argument: str | None = None,
                 remedy: tuple[str, str] | None = None) -> None:
        super().__init__(*args)
        self.argument = argument
        self.remedy = remedy


class InputError(FsdecoupleError):
    """A data file (calibration set, voltage log) cannot be used as it is."""


class ConfigError(FsdecoupleError):
    """The YAML configuration or a command-line setting is invalid."""


class ModelFileError(FsdecoupleError):
    """A model file is not a usable fsdecouple model."""


def printable(text: object, keep: str = "", *, spaces: bool = False) -> str:
    """``text`` with control characters (a newline in a file name) escaped as repr does,
    so that a message stays on one line; other characters, accents too, are kept, and so
    are the characters of ``keep`` (the console keeps its own line breaks) and, with
    ``spaces``, Unicode spaces (a no-break space in a spreadsheet's header).  The one
    function for user text on the terminal: the CLI's consoles apply it to everything."""
    text = str(text)
    if text.isprintable():
        return text
    escaped = ("C",) if spaces else ("C", "Z")
    return "".join(
        c if c == " " or c in keep or not unicodedata.category(c).startswith(escaped)
        # a file name's byte that is not UTF-8 (os.fsdecode's U+DC80..U+DCFF): as that byte
        else f"\\x{ord(c) - 0xDC00:02x}" if 0xDC80 <= ord(c) <= 0xDCFF
        else repr(c)[1:-1]
        for c in text
    )


def excerpt(text: object, limit: int = 60) -> str:
    """A value from a file, quoted in a message: one line, at most about ``limit`` characters."""
    text = printable(text)
    if len(text) <= limit:
        return text
    return f"{text[:limit]}... ({len(text)} characters)"


def where(file: str | Path | None, row: int | None = None, column: str | None = None) -> str:
    """Format a location as ``file, row 17, column 'uy'`` for error messages.

    Rows are counted as a spreadsheet shows them: the header is row 1.
    """
    parts = []
    if file is not None:
        parts.append(printable(file))
    if row is not None:
        parts.append(f"row {row}")
    if column is not None:
        parts.append(f"column '{excerpt(column)}'")
    return ", ".join(parts)
