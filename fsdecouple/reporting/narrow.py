"""Tables on a narrow terminal: split into parts that fit, never cut.

rich fits a table wider than the terminal by wrapping its cells, and where a column
may not wrap (a figure, a gamma) by cutting it or dropping whole columns: ``cv`` at
80 columns lost its svr column, the method the tool is about.  :func:`fit_width`
instead splits such a table by columns into parts that each fit.  Every part repeats
the table's key columns (``round`` and ``test``: :data:`KEY_COLUMNS`, 1 unless a table
says otherwise), and a column group (a header whose first line names the group, its
followers' first lines empty, as the gamma table's methods) is kept whole in one part.

Output that goes to a file or a pipe has no width, and its tables are never split (a CI
log is read with grep): their cells that may wrap wrap at REDIRECTED columns, so a guessed
reason in ``init``'s table no longer makes a CI log 396 characters wide.
"""

from __future__ import annotations

import copy

from rich.console import Console
from rich.table import Table
from rich.text import Text

REDIRECTED = 160  # [columns] tables in a file or a pipe: a wide terminal's width
KEY_COLUMNS = "fsdecouple_key_columns"  # attribute a table sets: how many leading key columns


def needed_width(console: Console, table: Table) -> int:
    """The narrowest the table renders without cutting a cell that may not wrap: such a
    column at its widest, any other at its narrowest (rich's own column measure, private;
    measured on a wide console, as rich clamps a measure to the console's width)."""
    options = console.options.update_width(1 << 20)
    widths = (table._measure_column(console, options, col) for col in table.columns)
    return table._extra_width + sum(m.maximum if col.no_wrap else m.minimum
                                    for col, m in zip(table.columns, widths, strict=True))


def _groups(table: Table, keys: int) -> list[list[int]]:
    """The non-key columns, in groups that stay together (a header led by an empty line
    continues the group before it)."""
    groups: list[list[int]] = []
    for i, col in enumerate(table.columns[keys:], start=keys):
        header = col.header.plain if isinstance(col.header, Text) else str(col.header)
        if groups and "\n" in header and not header.split("\n", 1)[0].strip():
            groups[-1].append(i)
        else:
            groups.append([i])
    return groups


def _part(table: Table, columns: list[int], first: bool, last: bool) -> Table:
    part = copy.copy(table)
    part.columns = []
    for n, i in enumerate(columns):
        col = copy.copy(table.columns[i])
        col._index = n  # rich's own bookkeeping (private)
        part.columns.append(col)
    if not first and table.title is not None:
        part.title = Text.assemble(table.title, " (continued)") if isinstance(table.title, Text) \
            else f"{table.title} (continued)"
    if not last:
        part.caption = None
    return part


def fit_width(table: Table, console: Console, width: int | None = None) -> list[Table]:
    """``table`` as it is when it fits ``width`` (default: the console's), else its parts."""
    width = console.width if width is None else width
    if needed_width(console, table) <= width:
        return [table]
    keys = min(getattr(table, KEY_COLUMNS, 1), len(table.columns) - 1)
    parts: list[list[int]] = []
    current: list[int] = []
    for group in _groups(table, keys):
        trial = [*range(keys), *current, *group]
        if current and needed_width(console, _part(table, trial, True, True)) > width:
            parts.append(current)
            current = list(group)
        else:
            current += group
    parts.append(current)
    if len(parts) == 1:
        return [table]  # one group wider than the terminal: rich wraps what it can
    return [_part(table, [*range(keys), *p], i == 0, i == len(parts) - 1)
            for i, p in enumerate(parts)]
