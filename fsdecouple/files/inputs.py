"""Files in: reading a user's file with one-line errors, size limits, FIFOs, natural order."""

from __future__ import annotations

import contextlib
import csv
import errno
import os
import re
import select
import stat
from collections.abc import Iterator
from pathlib import Path

from ..errors import InputError, printable


@contextlib.contextmanager
def reading(path: str | Path, what: str = "a CSV file", *, noun: str = "",
            error: type = InputError) -> Iterator[None]:
    """Turn the OS errors of opening and reading ``path`` into one-line ``error``s.

    ``noun`` names the kind of input ("config": "config file not found", "cannot read
    config (...)"); the path's control characters are escaped: the message is one line."""
    name, kind = printable(path), f"{noun} " if noun else ""
    try:
        yield
    except FileNotFoundError:
        raise error(f"{name}: {kind}file not found") from None
    except IsADirectoryError:
        raise error(f"{name}: is a directory, expected {what}") from None
    except UnicodeDecodeError:
        why = "not a UTF-8 text file"
        where_ = _first_non_utf8(path)
        if where_ and not noun:  # a spreadsheet's Latin-1 export of 'Temp [°C]': say where
            raise error(f"{name}, {where_} is not UTF-8 text; save the file as UTF-8 (a "
                        "spreadsheet's 'CSV UTF-8')") from None
        raise error(f"{name}: cannot read {noun} ({why})" if noun else f"{name}: {why}") from None
    except OSError as err:
        raise error(f"{name}: cannot read {kind}({err.strerror})") from None


def _first_non_utf8(path: str | Path, limit: int = 64 << 20) -> str | None:
    """``row R, column 'C': 'cell'`` of the first byte of a regular file (up to ``limit``
    bytes) that is not UTF-8, the column by the header's names (',' or ';' separated);
    None when it cannot be said."""
    try:
        p = Path(path)
        if not p.is_file():
            return None
        with p.open("rb") as fh:
            body = fh.read(limit)
        body.decode("utf-8")
        return None
    except UnicodeDecodeError as err:
        pos = err.start
    except OSError:
        return None
    if body[:2] in (b"\xff\xfe", b"\xfe\xff") or b"\x00" in body[:4096]:
        return None  # UTF-16 or binary: no cell to name, the file is the matter
    start, end = body.rfind(b"\n", 0, pos) + 1, body.find(b"\n", pos)
    line = body[start:len(body) if end < 0 else end].removesuffix(b"\r")
    head = body.split(b"\n", 1)[0].removesuffix(b"\r").decode("utf-8", "backslashreplace")
    sep = ";" if head.count(";") > head.count(",") else ","
    names = next(csv.reader([head], delimiter=sep), [])
    cells = next(csv.reader([line.decode("latin-1")], delimiter=sep), [])
    offset, column, cell = start, None, line.decode("utf-8", "backslashreplace")
    for j, c in enumerate(cells):  # the cell holding the byte, by its position
        width = len(c.encode("latin-1")) + 1
        if offset <= pos < offset + width:
            column = names[j] if j < len(names) else None
            cell = c.encode("latin-1").decode("utf-8", "backslashreplace")
            break
        offset += width
    row = body.count(b"\n", 0, pos) + 1
    shown = printable(cell)[:60]
    return f"row {row}" + (f", column '{printable(column)}'" if column else "") + f": '{shown}'"


# A FIFO (named pipe) given as an input waits this long for its first bytes, then is
# refused: a FIFO that no process writes to would otherwise block open() for ever.
FIFO_WAIT = 20.0  # seconds


def open_input(path: str | Path):
    """Open ``path`` for reading (binary), never hanging on a FIFO without a writer.

    The file is opened non-blocking, which returns at once whatever it is; a FIFO
    (a named pipe, ``/dev/stdin`` fed by a pipe) is then polled for up to
    :data:`FIFO_WAIT` seconds for data or its writer's end, and refused with one
    line if neither comes.  Reads after that block as usual.  A directory raises
    :class:`IsADirectoryError` (for :func:`reading`).
    """
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    try:
        mode = os.fstat(fd).st_mode
        if stat.S_ISDIR(mode):
            raise IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR), str(path))
        if stat.S_ISFIFO(mode):
            poll = select.poll()
            poll.register(fd, select.POLLIN)
            if not poll.poll(int(FIFO_WAIT * 1000)):
                raise InputError(
                    f"{printable(path)}: a pipe with no data after {FIFO_WAIT:g} s (no process "
                    "writing to it?); not read"
                )
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


MB = 1 << 20
# Size limits per input kind, checked before reading (README, "Errors and exit codes").
CONFIG_LIMIT = 1 * MB
MODEL_LIMIT = 64 * MB
CV_LIMIT = 64 * MB
CALIBRATION_LIMIT = 64 * MB  # per file: a calibration is thousands of rows, not millions
TASK_LIMIT = 256 * MB  # cv --task and --task-forces: read whole, ~10 million rows


def _size(n: int) -> str:
    return f"{n / MB:.0f} MB" if n >= MB else f"{n} bytes"


def read_bounded(path: str | Path, limit: int, what: str, error: type = InputError) -> bytes:
    """The bytes of ``path``, refused with one line if there are more than ``limit``.

    A regular file is measured (``fstat``) before anything is read, so a 1 GB sparse file
    costs nothing; anything else (``/dev/zero``, a pipe) is read to at most ``limit + 1``
    bytes.  OS errors (not found, a directory) are the caller's."""
    with open_input(path) as fh:
        st = os.fstat(fh.fileno())
        if stat.S_ISREG(st.st_mode) and st.st_size > limit:
            raise error(f"{printable(path)}: {_size(st.st_size)}, larger than the {_size(limit)} "
                        f"limit for {what}; not read")
        data = fh.read(limit + 1)
    if len(data) > limit:
        raise error(f"{printable(path)}: more than the {_size(limit)} limit for {what}; not read")
    return data


def natural_key(name: str) -> list:
    """Sort ``rep2`` before ``rep10``."""
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]
