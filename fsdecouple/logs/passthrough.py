"""Which columns of a log pass through to apply's output, and its lines without the others."""

from __future__ import annotations

import collections
import csv
import io
from dataclasses import dataclass

import pyarrow as pa
import pyarrow.compute as pc


@dataclass(frozen=True)
class Dropped:
    """A log column not passed through to the output: its 1-based position, name and why."""

    column: int
    name: str
    reason: str


def passed_columns(header: list[str], mapped: list[str]) -> tuple[list[int], list[Dropped]]:
    """The columns of a log passed through to the output, and those dropped, with why.

    The layouts ``fit`` reads (and ``init`` describes): columns without a name,
    names repeated (never a mapped one: :func:`~fsdecouple.data.csv_text.require_columns`
    refuses that), and a side table right of the first unnamed column when every
    mapped column is left of it.  Every other column passes through.
    """
    used = {header.index(n) for n in mapped}
    why: dict[int, str] = {}
    gap = next((i for i, n in enumerate(header) if not n), None)
    if gap is not None and used and max(used) < gap:
        why.update({i: f"right of the unnamed column {gap + 1}: a side table"
                    for i in range(gap + 1, len(header)) if header[i]})
    count = collections.Counter(n for i, n in enumerate(header) if i not in why)
    for i, n in enumerate(header):
        if not n:
            why[i] = "no header name"
        elif count[n] > 1 and i not in used and i not in why:
            why[i] = f"header name repeated ({count[n]} columns)"
    keep = [i for i in range(len(header)) if i not in why]
    return keep, [Dropped(i + 1, header[i], why[i]) for i in sorted(why)]


def kept_fields(line: bytes, keep: list[int], width: int, sep: str) -> bytes:
    """One CSV line (no line end) cut down to the fields ``keep``, re-quoted where needed.

    The bytes of each kept field are kept (a field that is not UTF-8 passes as it is).
    """
    text = line.decode("utf-8", "surrogateescape")
    fields = next(csv.reader([text], delimiter=sep)) if text else []
    fields += [""] * (width - len(fields))
    return csv_row([fields[j] for j in keep], sep).encode("utf-8", "surrogateescape")


def csv_row(fields, sep: str) -> str:
    """``fields`` as one CSV line (no line end): quoted where one holds ``sep``, a quote or
    a line end (the csv module's minimal quoting, as pandas reads it back)."""
    buf = io.StringIO()
    # the line end given, and cut: the writer quotes the fields that hold one of its characters
    csv.writer(buf, delimiter=sep, lineterminator="\r\n").writerow(fields)
    return buf.getvalue()[:-2]


def kept_lines(lines: pa.Array, keep: list[int], sep: str) -> pa.Array:
    """:func:`kept_fields` of whole lines without quotes, vectorised: split and re-joined."""
    parts = pc.split_pattern(lines, sep.encode())
    return pc.binary_join_element_wise(*[pc.list_element(parts, j) for j in keep], sep.encode())
