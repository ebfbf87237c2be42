"""Calibration files: the CSVs of a calibration set and task logs with true forces."""

from __future__ import annotations

import hashlib
import io
import os
import re
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..config import Settings
from ..errors import InputError, excerpt, printable, where
from ..files.inputs import CALIBRATION_LIMIT, TASK_LIMIT, natural_key, read_bounded, reading
from ..temperature_units import DEFAULT_TEMPERATURE, to_celsius
from ..temperature_units import column as temperature_column
from ..temperature_units import unit as temperature_unit
from .csv_text import (
    HEADER_ROW,
    first_difference,
    read_cells,
    read_csv_text,
    read_header,
    require_columns,
    to_numbers,
)
from .guesses import applied_load
from .magnitudes import adc_bits
from .poses import average_poses, is_pose_log, pose_note, timestamp_column
from .rails import at_rail, ranges

if TYPE_CHECKING:
    import pandas as pd


def list_calibration(path: str | Path) -> tuple[list[Path], list[Path]]:
    """The CSV files of a calibration set, and the hidden CSVs it skips, from one listing.

    A directory's files are sorted naturally (``rep2`` before ``rep10``); hidden
    ones (macOS ``._rep1.csv``, editor backups) are returned apart.  A file is a
    set of its own.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: calibration data not found")
    if not path.is_dir():
        return [path], []
    entries = [p for p in path.iterdir() if p.suffix.lower() == ".csv"]
    for p in sorted(entries, key=lambda p: natural_key(p.name)):
        if not p.name.startswith(".") and not p.is_file():
            # a repetition that cannot be read is never skipped without a word
            what = ("a symbolic link to a missing file" if p.is_symlink() and not p.exists()
                    else "a directory" if p.is_dir() else "not a regular file (a device or pipe?)")
            raise InputError(f"{p}: named like a repetition file but is {what}; "
                             "restore the file or move it out of the calibration directory")
    files = sorted((p for p in entries if not p.name.startswith(".")),
                   key=lambda p: natural_key(p.name))
    if not files:
        raise InputError(f"{path}: directory holds no .csv files")
    return files, sorted(p for p in entries if p.name.startswith("."))


# Repetition labels are whole numbers 1 .. 2**53, read exactly from their text: a
# label through a float would merge 2**53 and 2**53 + 1, and 1e20 would wrap.
MAX_REPETITION = 2**53
LABEL_TEXT = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?", re.ASCII)  # a number, ASCII only


def _repetition_labels(cells, path: Path, column: str, rows, decimal: str) -> np.ndarray:
    """Repetition numbers as exact integers, or name the first cell that is not one.

    ``cells``: an object array of the column's cells (``str``)."""
    text = np.asarray([str(c).strip().replace(decimal, ".") for c in cells], dtype=object)
    uniq, inverse = np.unique(text, return_inverse=True)  # a few labels, many rows
    values, bad = np.zeros(len(uniq), dtype=np.int64), np.zeros(len(uniq), dtype=bool)
    for j, t in enumerate(uniq):
        try:
            if not LABEL_TEXT.fullmatch(t):  # Python reads 1_0 as 10 and '٣' (Arabic) as 3;
                raise InvalidOperation       # a spreadsheet reads neither
            value = Decimal(t)
        except InvalidOperation:
            bad[j] = True
            continue
        if not value.is_finite() or value != value.to_integral_value() \
                or not 1 <= value <= MAX_REPETITION:
            bad[j] = True
        else:
            values[j] = int(value)
    if bad.any():
        i = int(np.argmax(bad[inverse]))
        big = _too_big(text[i])
        raise InputError(
            f"{where(path, int(rows[i]), column)}: {excerpt(str(cells[i]).strip())!r} is "
            f"not a repetition number (1, 2, ...{', at most 2**53' if big else ''})"
        )
    return values[inverse]


def _axis_labels(cells: np.ndarray, labels: dict[str, str]) -> np.ndarray:
    """The sweep label of each stripped ``axis`` cell (``labels``: lower-cased cell to label),
    None where it names none; each distinct cell looked up once."""
    import pandas as pd

    uniq, inverse = np.unique(cells, return_inverse=True)
    if all(u.isascii() for u in uniq):
        lower = [u.lower() for u in uniq]
    else:  # pandas' str.lower, as the table's reader always had: İ is i there, not Python's i̇
        lower = pd.Series(uniq, dtype="str").str.lower().tolist()
    return np.array([labels.get(u) for u in lower], dtype=object)[inverse.ravel()]


def _too_big(text: str) -> bool:
    try:
        value = Decimal(text)
    except InvalidOperation:
        return False
    return value.is_finite() and value > MAX_REPETITION


def calibration_files(path: str | Path) -> list[Path]:
    """The CSV files of a calibration set: a directory (sorted naturally) or one file."""
    return list_calibration(path)[0]


@dataclass(frozen=True)
class CalibrationTable:
    """A calibration set as read: one long table in file order, and what was seen on the way.

    ``table`` has columns ``repetition, axis, file, row, fx..uz`` with forces in N
    and voltages in V after the config's ``scale``; ``axis`` is empty when the
    files have no axis column.
    """

    table: pd.DataFrame
    skipped: list[str]
    files: tuple[tuple[str, str], ...]  # (path, SHA-256) of every file read
    hidden: list[Path]
    warnings: tuple[str, ...] = ()
    noise: np.ndarray | None = None  # pose logs: sigma of each averaged output (poses.py)
    excluded: tuple[tuple[str, int], ...] = ()  # (file, line) dropped by --exclude unread


def read_calibration_table(path: str | Path, settings: Settings,
                           strict: bool = False, exclude=()) -> CalibrationTable:
    """Read a calibration set into one long table in file order.

    The directory is listed once and each file read once (its digest, header
    and cells all come from the same bytes).  ``exclude``: ``(file, line)`` pairs
    (:func:`fsdecouple.data.calibration.parse_exclude`) dropped before their cells are
    read, so a line that cannot be parsed can be excluded too; each pair found is
    marked in ``excluded``.
    """
    import pandas as pd

    files, hidden = list_calibration(path)
    single = len(files) == 1 and not Path(path).is_dir()
    frames, skipped, digests, warnings = [], [], [], []
    excluded: list[tuple[str, int]] = []
    poses: list = []  # pose logs: (file, header, runs averaged, points)
    counts: list[np.ndarray] = []  # raw ADC counts as read, for the converter's range (rails.py)
    pose_ss, pose_dof, pose_inv, pose_n = 0.0, 0, 0.0, 0  # pose logs (poses.py)
    cols = settings.columns
    layout = settings.layout
    numeric = {c: cols[c] for c in (*layout.loads, *layout.outputs)}
    for rep_index, f in enumerate(files, start=1):
        name = str(f)
        if not name.isascii():
            try:  # the name is recorded in tables, model files and messages as text
                name.encode("utf-8")
            except UnicodeEncodeError:  # legal on Linux (a Latin-1 file share): read it, and
                # record its name with the byte that is not UTF-8 shown as \xff
                name = os.fsencode(f).decode("utf-8", "backslashreplace")
        with reading(f):  # a FIFO: read once, never waited on for ever
            data = read_bounded(f, CALIBRATION_LIMIT, "a calibration file")
        nul = data.find(b"\x00")
        if nul >= 0:  # NUL padding (a crashed logger, a pre-allocated file): not text
            row = data.count(b"\n", 0, nul) + 1
            raise InputError(f"{where(f, row)}: a NUL byte: not a UTF-8 text file (binary, "
                             "UTF-16, or padding from a crashed writer?)")
        digests.append((name, hashlib.sha256(data).hexdigest()))
        header = read_header(f, settings, data, strict=False)
        if {f"{c}_raw" for c in layout.outputs} <= set(header):
            # the tidy CSV of `ingest -o`: zero-corrected already, and every repetition
            raise InputError(
                f"{where(f, HEADER_ROW)}: this is the output of 'fsdecouple ingest -o' (it has "
                f"{layout.outputs[0]}_raw), not a repetition; move it out of the calibration directory"
            )
        _suggest_init(header, settings, numeric, f, path)
        require_columns(header, numeric, f, calibration=True)
        for c in layout.outputs:  # a reading mapped to a reference column: a swapped config
            if applied_load(cols[c]):
                raise InputError(f"{where(f, HEADER_ROW, cols[c])}: output {c} is mapped to "
                                 f"'{cols[c]}', named like an applied load; map {c} to the "
                                 "sensor's own reading in the config's columns")
        # a single CSV without a repetition column is one repetition
        numbered = single and cols["repetition"] in header
        mapped = {name: name for name in numeric.values()}
        t_name = temperature_column(settings)  # columns: {temperature: ...} (issue 31)
        if t_name is None and DEFAULT_TEMPERATURE in header:  # the default name, as fx's is fx
            t_name = DEFAULT_TEMPERATURE
        if t_name is not None:
            mapped[t_name] = t_name
        mapped.update({cols[c]: cols[c] for c in ("axis", "repetition")
                       if cols[c] in header and (c != "repetition" or numbered)})
        require_columns(header, mapped, f)
        # Columns the config does not map are ignored: they may have no name, a
        # duplicated one, or hold a side table.  Every field is still read, so a row
        # with more fields than the header is still refused.
        cells, spaced = read_cells(data, settings, f, len(header))
        raw = cells[:, [header.index(n) for n in mapped]]  # the mapped columns, in order
        at = {n: j for j, n in enumerate(mapped)}
        if not len(raw):
            raise InputError(f"{f}: header only, no data rows")
        rows = np.arange(len(raw)) + HEADER_ROW + 1
        mine = {line for name, line in exclude if _names_file(name, f)}
        if mine:  # --exclude FILE:LINE, before any cell of the line is read
            gone = np.isin(rows, sorted(mine))
            excluded.extend((str(f), int(r)) for r in rows[gone])
            if timestamp_column(header) is not None:
                # a pose log: a line of a pose names the pose (one calibration point), so
                # the run of consecutive lines with its load cells goes with it
                load_cells = raw[:, [at[cols[c]] for c in layout.loads]]
                key = np.array(["\x1f".join(r) for r in load_cells.tolist()], dtype=object)
                run = np.cumsum(np.r_[True, key[1:] != key[:-1]])
                if is_pose_log(np.bincount(run)):
                    gone = np.isin(run, run[gone])
            raw, rows = raw[~gone], rows[~gone]
        # one strip of every mapped cell: the blank checks and the numbers read it
        text = np.frompyfunc(str.strip, 1, 1)(raw) if spaced else raw
        empty = text == ""
        blank = empty.all(axis=1)
        if blank.any():
            for r in rows[blank]:
                skipped.append(f"{f}, row {r}: skipped, no value in any mapped column (a blank "
                               "row, or a side table running past the data)")
            raw, text, empty, rows = raw[~blank], text[~blank], empty[~blank], rows[~blank]
        # a row whose applied loads are all blank (a load not yet typed in): skipped with
        # a warning naming its lines, or refused in strict mode
        loads = [cols[c] for c in layout.loads]
        blanks = empty[:, [at[c] for c in loads]]
        noload = blanks.all(axis=1)
        if noload.any():
            lines = ("lines " if noload.sum() > 1 else "line ") + ", ".join(map(str, rows[noload]))
            if strict:
                raise InputError(f"{where(f, int(rows[noload][0]), loads[0])}: the applied loads "
                                 f"are blank ({lines}); strict mode refuses rows without a load",
                                 argument="strict")
            warnings.append(f"{f}, {lines}: applied loads blank; "
                            f"{'rows' if noload.sum() > 1 else 'row'} skipped (strict mode "
                            f"refuses {'them' if noload.sum() > 1 else 'it'})")
            raw, text, blanks, rows = raw[~noload], text[~noload], blanks[~noload], rows[~noload]
        # some applied loads blank (a cell not typed in): the row cannot be placed, skipped
        # with a warning naming its lines, or refused in strict mode
        partial = blanks.any(axis=1)
        if partial.any():
            lines = ("lines " if partial.sum() > 1 else "line ") + ", ".join(map(str, rows[partial]))
            i = int(np.argmax(partial))
            col = loads[int(np.argmax(blanks[i]))]
            if strict:
                raise InputError(f"{where(f, int(rows[i]), col)}: an applied load is blank "
                                 f"({lines}); strict mode refuses rows without every load",
                                 argument="strict")
            several = partial.sum() > 1
            shown = "; ".join(
                (f"line {r}: " if several else "")
                + ", ".join(repr(c) for c, b in zip(loads, bl, strict=True) if b)
                for r, bl in zip(rows[partial][:5], blanks[partial][:5], strict=True))
            warnings.append(f"{f}, {lines}: an applied load is blank ({shown}"
                            f"{'; ...' if partial.sum() > 5 else ''}); "
                            f"{'rows' if several else 'row'} skipped (strict mode refuses "
                            f"{'them' if several else 'it'})")
            raw, text, rows = raw[~partial], text[~partial], rows[~partial]
        if not len(raw):
            raise InputError(f"{f}: header only, no data rows")
        # the file's columns, as the table's: built into one DataFrame after the last file
        out = {"file": np.full(len(rows), name, dtype=object), "row": rows}
        if numbered:
            out["repetition"] = _repetition_labels(text[:, at[cols["repetition"]]], f,
                                                   cols["repetition"], rows, settings.decimal)
        else:  # a directory's file order, or the one CSV
            out["repetition"] = np.full(len(rows), rep_index, dtype=np.int64)
        if cols["axis"] in header:
            # a label (x; fx for a named component) or the component's load column name
            j = at[cols["axis"]]
            axis = _axis_labels(text[:, j], layout.label_map())
            bad = np.array([a is None for a in axis], dtype=bool)
            if bad.any():
                i = int(np.argmax(bad))
                names = list(layout.labels)
                raise InputError(
                    f"{where(f, int(rows[i]), cols['axis'])}: "
                    f"{excerpt(repr(raw[i, j]))}, expected "
                    f"{', '.join(names[:-1])} or {names[-1]}"
                )
            out["axis"] = axis
        else:
            out["axis"] = np.full(len(rows), "", dtype=object)
        for canonical, name in numeric.items():
            values = to_numbers(text[:, at[name]], f, name, rows, settings.decimal, stripped=True)
            # check each cell before scaling so the message quotes the file's value
            out[canonical] = values * settings.scale[canonical]
        if settings.output_unit == "count":  # the converter's range, from the samples (rails.py)
            counts.append(np.column_stack([out[c] for c in layout.outputs]))
        if t_name is not None:  # in degC, as a fitted model's temperature terms are
            out["temperature"] = to_celsius(
                to_numbers(text[:, at[t_name]], f, t_name, rows, settings.decimal, stripped=True),
                temperature_unit(settings))
        if timestamp_column(header) is not None:  # a pose log: samples averaged per load
            keys = [*layout.loads, "repetition", "axis"]
            out, ss, dof, runs, inverse = average_poses(out, keys, list(layout.outputs))
            if runs:
                pose_ss, pose_dof = pose_ss + ss, pose_dof + dof
                pose_inv, pose_n = pose_inv + inverse, pose_n + len(runs)
            poses.append((f, header, runs, out))
        frames.append(out)
    if len(poses) == len(files) > 1 and len(poses[0][3]["row"]) == 1:
        # a directory of pose files: one static pose per file, all one calibration set
        _one_pose_each(poses)
        for frame in frames:
            frame["repetition"] = np.ones(len(frame["row"]), dtype=np.int64)
        runs = [(f"{Path(f).name}, lines {r[0]}-{r[1]}", *r[2:]) for f, _, rs, _ in poses for r in rs]
        warnings.append(pose_note(Path(path), [(a, "", *rest) for a, *rest in runs],
                                  sum(r[1] for r in runs), files=len(poses)))
    else:
        warnings += [pose_note(f, runs, sum(r[2] for r in runs)) for f, _, runs, _ in poses if runs]
    columns = ["repetition", "axis", "file", "row", *layout.loads, *layout.outputs]
    if any("temperature" in frame for frame in frames):
        columns.append("temperature")
        for frame in frames:  # not in every file: refused below, once the set is read
            frame.setdefault("temperature", np.full(len(frame["row"]), np.nan))
    table = {c: np.concatenate([frame[c] for frame in frames]) for c in columns}
    bits = adc_bits(np.concatenate(counts)) if counts else None
    u = np.column_stack([table[c] for c in layout.outputs])
    known = ranges(settings, layout.outputs, u, bits)
    pose_files = {str(f) for f, *_ in poses}
    posed = np.concatenate([np.full(len(frame["row"]), frame["file"][0] in pose_files)
                            for frame in frames])
    keep = np.ones(len(table["row"]), dtype=bool)
    if known and posed.any():  # a channel at a rail on a pose (rails.py)
        keep[posed], notes = at_rail(pd.DataFrame({c: v[posed] for c, v in table.items()}),
                                     layout.outputs, known, strict, layout.loads)
        warnings.extend(notes)
    if "temperature" in table and np.isnan(table["temperature"][keep]).any():
        f = table["file"][keep][np.isnan(table["temperature"][keep])][0]
        raise InputError(f"{where(f, HEADER_ROW)}: no column 'temperature', which the set's "
                         "other files have; every repetition needs its temperature")
    # training order is file order: repetition, then row (stable)
    order = np.flatnonzero(keep)
    order = order[np.argsort(table["repetition"][order], kind="stable")]
    frame = pd.DataFrame(table)  # one frame, its string columns typed as pandas reads text
    if len(order) < len(keep) or (order[1:] < order[:-1]).any():
        frame = frame.iloc[order].reset_index(drop=True)
    noise = np.sqrt(pose_ss / pose_dof * pose_inv / pose_n) if pose_dof else None
    return CalibrationTable(frame, skipped, tuple(digests), hidden, tuple(warnings), noise,
                            tuple(excluded))


def _suggest_init(header, settings: Settings, numeric: dict, f: Path, path) -> None:
    """The built-in columns (no config, or one without ``columns:``) none of which the file
    has: a file from another rig, whose config ``init`` guesses; say so, not "did you mean"."""
    if settings.components is not None or settings.columns != Settings().columns:
        return
    if any(name in header for name in numeric.values()):
        return  # some mapped: a typo in a paper-layout file, which require_columns names
    shown = printable(str(path))
    raise InputError(f"{where(f, HEADER_ROW)}: none of the built-in columns "
                     f"({', '.join(numeric.values())}) is in the header; for this file's "
                     f"layout run 'fsdecouple init {shown} -o sensor.yaml', check it, then "
                     "fit with -c sensor.yaml")


def _one_pose_each(poses) -> None:
    """A pose directory's files: each one static pose, all in the first file's layout."""
    first, header0 = poses[0][0], poses[0][1]
    for f, header, _, out in poses[1:]:
        if header != header0:
            j, found, want = first_difference(header, header0)
            raise InputError(f"{where(f, HEADER_ROW)}: column {j + 1} is {found}, {first.name} has "
                             f"{want} there; the files of a pose directory share one layout")
        if len(out["row"]) > 1:
            line = int(out["row"][1])
            raise InputError(f"{where(f, line)}: the applied loads change here (from line "
                             f"{int(out['row'][0])}'s); a pose file holds one static pose "
                             "(split it into one file per pose)")


def _names_file(name: str, f: Path) -> bool:
    """Whether ``--exclude``'s FILE names file ``f``: by its path, or by its name alone."""
    return str(f) == name if "/" in name else Path(name).name == f.name or str(f) == name



def read_task_log(
    voltages: str | Path, forces: str | Path, settings: Settings
) -> tuple[np.ndarray, np.ndarray]:
    """A voltage log and its true forces, as ``simulate`` writes them, row for row.

    Returns ``(u, f)``, shape (n, N) each, in V and N (config columns and scales).
    """
    out = []
    layout = settings.layout
    for path, canon in ((Path(voltages), layout.outputs), (Path(forces), layout.loads)):
        with reading(path):  # read once: it may be a pipe; never beyond the limit
            data = read_bounded(path, TASK_LIMIT, "a task log")
        header = read_header(path, settings, data)
        names = {c: settings.columns[c] for c in canon}
        require_columns(header, names, path)
        raw = read_csv_text(io.BytesIO(data), settings, path=path)
        if raw.empty:
            raise InputError(f"{path}: header only, no data rows")
        out.append(np.column_stack([
            to_numbers(raw[n], path, n, HEADER_ROW + 1, settings.decimal) * settings.scale[c]
            for c, n in names.items()
        ]))
    u, f = out
    if len(u) != len(f):
        raise InputError(
            f"{forces}: {len(f)} rows, but {voltages} has {len(u)}; the true forces must "
            "match the voltage log row for row"
        )
    return u, f
