"""Files in: reading a user's file with one-line errors, size limits, FIFOs, natural order."""

from __future__ import annotations

import contextlib
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
        said = None if noun else non_utf8_message(name, path)
        if said:  # a spreadsheet's Latin-1 export of 'Temp [°C]': say where
            raise error(said) from None
        raise error(f"{name}: cannot read {noun} ({why})" if noun else f"{name}: {why}") from None
    except OSError as err:
        raise error(f"{name}: cannot read {kind}({err.strerror})") from None


def non_utf8_message(name: str, source, sep: str | None = None,
                     limit: int = 64 << 20) -> str | None:
    """The one-line refusal of a CSV that is not UTF-8, naming the row, column and cell of
    its first such byte (:func:`non_utf8_cell`): ``source`` a regular file's path or a
    bytes buffer, of which the first ``limit`` bytes are read.  None when the place cannot
    be said (UTF-16, binary, unreadable): the caller's file-only message then stands."""
    try:
        if isinstance(source, str | Path):
            if not Path(source).is_file():
                return None
            with open(source, "rb") as fh:
                body = fh.read(limit)
        else:
            body = source.getvalue() if hasattr(source, "getvalue") else None
            if not isinstance(body, bytes):
                return None
    except OSError:
        return None
    where_ = non_utf8_cell(body, sep, truncated=len(body) == limit)
    return (None if where_ is None else f"{name}, {where_} is not UTF-8 text; save the file as "
            "UTF-8 (a spreadsheet's 'CSV UTF-8')")


def non_utf8_cell(body: bytes, sep: str | None = None, truncated: bool = False, *,
                  header: list[str] | None = None, first_row: int = 1) -> str | None:
    """Where in ``body`` the first byte that is not UTF-8 lies: ``row R, column 'C':
    'cell'``, or None (valid; a whole file in UTF-16 or binary).

    ``body`` is a CSV file's bytes from its header (row 1), or with ``header`` (the
    file's column names) a block of its whole lines from spreadsheet row ``first_row``
    (a log's). The line is split on ``sep`` (else the header's most frequent of , ; and
    tab) outside double quotes, byte by byte, so a quoted field's separators and doubled
    quotes do not shift the cell named.  ``truncated``: ``body`` is a file's first bytes
    only."""
    try:
        body.decode("utf-8")
        return None
    except UnicodeDecodeError as err:
        if truncated and err.reason == "unexpected end of data":
            return None  # the read was cut inside a character
        pos = err.start
    if header is None and (body[:2] in (b"\xff\xfe", b"\xfe\xff") or b"\x00" in body[:4096]):
        return None  # UTF-16 or binary: no cell to name, the file is the matter

    def fields(line: bytes, at: int = -1) -> tuple[list[bytes], int, int]:
        """The line's cells, the index of the one holding byte ``at`` and that byte's
        offset in it."""
        out, cell, quoted, index, offset = [], bytearray(), False, -1, 0
        for i, c in enumerate(line):
            if i == at:
                index, offset = len(out), len(cell)
            if c == 0x22:
                quoted = not quoted
            elif c == ord(delim) and not quoted:
                out.append(bytes(cell))
                cell = bytearray()
                continue
            cell.append(c)
        out.append(bytes(cell))
        return out, index, offset

    head = body.split(b"\n", 1)[0].removesuffix(b"\r") if header is None else b""
    delim = sep or max((",", ";", "\t"), key=lambda d: head.count(d.encode()))
    start = body.rfind(b"\n", 0, pos) + 1
    end = body.find(b"\n", pos)
    line = body[start:len(body) if end < 0 else end].removesuffix(b"\r")
    names = fields(head)[0] if header is None else [h.encode("utf-8", "surrogateescape") for h in header]
    cells, j, offset = fields(line, pos - start)

    def text(b: bytes, at: int = 0) -> str:
        """At most 60 characters of ``b``, around its byte ``at`` (the one not UTF-8)."""
        lo = max(0, min(at - 30, len(b) - 60))
        part = printable(b[lo:lo + 60].decode("utf-8", "backslashreplace").strip('"'))
        return ("..." if lo else "") + part + ("..." if lo + 60 < len(b) else "")

    column = text(names[j]) if 0 <= j < len(names) else None
    cell = text(cells[j], offset) if 0 <= j < len(cells) else text(line, pos - start)
    row = first_row + body.count(b"\n", 0, pos)
    return f"row {row}" + (f", column '{column}'" if column else "") + f": '{cell}'"


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
# Size limits per input kind, checked before reading (docs/errors.md, "Inputs").
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
