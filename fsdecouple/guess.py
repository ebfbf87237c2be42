"""Starting a config from a calibration file: guess columns, units, full scale.

``fsdecouple init`` reads one calibration CSV (header and values, with the
:mod:`csv` module, at most :data:`MAX_ROWS` rows) and guesses what the config
would say about it.  Every guess carries its reason, which goes into the YAML
as a comment and into the printed table, because a guess nobody can check is
worse than none.

The reading here is lenient on purpose (empty and duplicated header names,
side tables to the right, text in number columns): it only has to find the
data, not to validate it; ``fsdecouple ingest`` does that with the config.
"""

from __future__ import annotations

import csv
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from .axes import AXES, FORCE_COLUMNS, VOLTAGE_COLUMNS
from .errors import InputError
from .iotools.files import atomic_write, check_output, reading, refuse_overwriting_input

MAX_ROWS = 100_000  # enough for any calibration; bounds a wrong file's cost

REQUIRED = (*FORCE_COLUMNS, *VOLTAGE_COLUMNS)
OPTIONAL = ("axis", "repetition")
KEYS = (*OPTIONAL[::-1], *REQUIRED)  # the order the config lists them

LOAD_UNITS = ("N", "kN", "gf", "kgf", "lbf")
OUTPUT_UNITS = ("V", "mV", "uV", "count", "mV/V")

# unit words as they appear in headers ([gf], (kgf), _N, lbf), lower case
_LOAD_HINTS = {"n": "N", "kn": "kN", "gf": "gf", "g": "gf", "kgf": "kgf", "kg": "kgf",
               "lbf": "lbf", "lb": "lbf", "lbs": "lbf"}
_OUTPUT_HINTS = {"v": "V", "mv": "mV", "uv": "uV", "µv": "uV", "μv": "uV", "count": "count",
                 "counts": "count", "cnt": "count", "lsb": "count", "mv/v": "mV/V",
                 "mvv": "mV/V", "mv/v excitation": "mV/V"}
_UNIT_NAMES = {"N": "newton", "kN": "kilonewton", "gf": "gram-force", "kgf": "kilogram-force",
               "lbf": "pound-force", "V": "volt", "mV": "millivolt", "uV": "microvolt",
               "count": "ADC counts", "mV/V": "millivolt per volt of excitation"}

# names after units and separators are stripped (`Force_X [N]` -> "forcex")
_FORCE = re.compile(r"(?:f|force|load|applied|appliedforce|appliedload|standardload)([xyz])"
                    r"|([xyz])(?:force|load)")
_OUTPUT = re.compile(r"(?:u|v|volt|volts|voltage|sensor|out|output|signal|bridge|sg|strain)"
                     r"([xyz])|([xyz])(?:volt|voltage|output|signal|sensor)")
_CHANNEL = re.compile(r"(ch|chan|channel|adc|ain|ai|v)(\d+)")
_AXIS = {"axis", "loadaxis", "loadedaxis", "direction", "loaddirection"}
_REPETITION = {"repetition", "rep", "repeat", "run", "cycle", "trial", "repno", "repetitionno"}

_NUMBER = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?")
_INTEGER = re.compile(r"[+-]?\d+")
_SEPS = (",", ";", "\t")

# Above this largest |load| a load in newtons is unlikely for a lab force sensor:
# gram-force is the usual unit of weights-on-a-hanger calibrations.
GF_ABOVE = 5000.0
COUNT_ABOVE = 1e4  # integers this large are ADC counts, not volts or millivolts


@dataclass(frozen=True)
class Ignored:
    """A header column left unmapped: its 1-based position, name and why."""

    column: int
    name: str
    reason: str


@dataclass
class Guess:
    """What ``fsdecouple init`` guessed about one calibration file, with reasons.

    ``columns`` maps config keys (``fx`` .. ``uz``, ``axis``, ``repetition``) to
    header names; ``reasons`` holds one line per key and per guessed setting
    (``units``, ``full_scale``, ``min_repetitions``, ``scaling``, ``csv``).
    ``full_scale`` is in the data's load unit.
    """

    path: Path
    columns: dict[str, str]
    units: dict[str, str]
    full_scale: dict[str, float]
    min_repetitions: int
    scaling: str
    sep: str = ","
    decimal: str = "."
    reasons: dict[str, str] = field(default_factory=dict)
    ignored: list[Ignored] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    rows: int = 0
    config: Path | None = None

    def to_dict(self) -> dict[str, Any]:
        """The ``--json`` document."""
        return {
            "config": None if self.config is None else str(self.config),
            "data": str(self.path),
            "columns": dict(self.columns),
            "units": dict(self.units),
            "full_scale": dict(self.full_scale),
            "min_repetitions": self.min_repetitions,
            "scaling": self.scaling,
            "csv": {"sep": self.sep, "decimal": self.decimal},
            "rows": self.rows,
            "reasons": dict(self.reasons),
            "ignored": [i.name for i in self.ignored],
            "ignored_columns": [
                {"column": i.column, "name": i.name, "reason": i.reason} for i in self.ignored
            ],
            "notes": list(self.notes),
        }

    def to_yaml(self) -> str:
        """The commented config: every guessed value with a comment saying why."""
        out = [
            f"# Started by `fsdecouple init` from {_comment(str(self.path))}",
            f"# ({self.rows} data rows read). Values marked 'guessed' come from the header",
            "# and the magnitudes of the data: check each one before fitting.",
            "",
            "# Any name; taken from the data file's name.",
            f"sensor: {_scalar(self.path.stem or 'sensor')}",
            "",
            "# File column for each quantity.",
            "columns:",
        ]
        for key in KEYS:
            if key in self.columns:
                out.append(f"  {key}: {_scalar(self.columns[key])}"
                           f"   # guessed: {_comment(self.reasons[key])}")
            else:
                out.append(f"  # {key}: not mapped ({_comment(self.reasons[key])})")
        if self.ignored:
            out.append("# Ignored columns (not read):")
            out += [f"#   column {i.column} {_comment(_shown(i.name))}: {_comment(i.reason)}"
                    for i in self.ignored]
        out += [
            "",
            f"# guessed: {_comment(self.reasons['units'])}",
            f"units: {{load: {self.units['load']}, output: {self.units['output']}}}",
            "",
            f"# guessed: {_comment(self.reasons['full_scale'])}",
            "full_scale: {" + ", ".join(f"{a}: {_num(self.full_scale[a])}" for a in AXES) + "}",
            "",
            f"# guessed: {_comment(self.reasons['min_repetitions'])}",
            f"min_repetitions: {self.min_repetitions}",
            "",
            f"# {_comment(self.reasons['csv'])}",
            f"csv: {{sep: {json.dumps(self.sep)}, decimal: {json.dumps(self.decimal)}}}",
            "",
            f"# guessed: {_comment(self.reasons['scaling'])}",
            f"scaling: {self.scaling}",
        ]
        if self.notes:
            out += ["", "# Notes:"] + [f"#   {_comment(n)}" for n in self.notes]
        return "\n".join(out) + "\n"


def _scalar(value: str) -> str:
    """``value`` as a YAML scalar that reads back as the same string."""
    text = yaml.safe_dump([value], default_flow_style=True, width=1 << 30, allow_unicode=True)
    return text.strip()[1:-1]


def _comment(text: str) -> str:
    """Text that stays on one comment line (a header may hold a line break)."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def _shown(name: str) -> str:
    return f"'{name}'" if name else "(no name)"


def _num(v: float) -> str:
    return str(int(v)) if float(v).is_integer() else repr(float(v))


def nice_ceil(value: float) -> float:
    """The smallest 1, 2, 2.5 or 5 x 10^k that is >= ``value`` (> 0)."""
    k = math.floor(math.log10(value))
    for exp in (k - 1, k, k + 1):
        for m in (1.0, 2.0, 2.5, 5.0):
            nice = m * 10.0**exp
            if nice >= value * (1 - 1e-12):
                # 2.5 x 10^-1 is 0.25, not 0.25000000000000006
                return float(f"{nice:.12g}")
    raise AssertionError("unreachable")


# --- the header --------------------------------------------------------------------


@dataclass(frozen=True)
class _Name:
    compact: str  # lower case, units and separators removed
    hint: str | None  # unit word found ("gf", "mv/v"), lower case


def _parse_name(header: str) -> _Name:
    text = header.strip().lower()
    hints = re.findall(r"[\[(]([^\])]*)[\])]", text)
    text = re.sub(r"[\[(][^\])]*[\])]", " ", text)
    tokens = [t for t in re.split(r"[\s_\-]+", text.strip()) if t]
    if len(tokens) > 1 and (tokens[-1] in _LOAD_HINTS or tokens[-1] in _OUTPUT_HINTS):
        hints.append(tokens.pop())
    hint = next((h.strip() for h in hints if h.strip() in _LOAD_HINTS or h.strip() in
                 _OUTPUT_HINTS), None)
    return _Name(re.sub(r"[^0-9a-zµμ]", "", "".join(tokens)), hint)


@dataclass(frozen=True)
class _Candidate:
    key: str
    column: int  # 0-based
    rank: int  # 0 the config's own name, 1 a named pattern, 2 a numbered channel
    why: str


def _candidates(names: list[str], usable: list[int]) -> list[_Candidate]:
    found: list[_Candidate] = []
    families: dict[str, list[tuple[int, int]]] = {}
    for i in usable:
        n = _parse_name(names[i])
        unit = f", unit {n.hint} ({_UNIT_NAMES[_unit_of(n.hint)]})" if n.hint else ""
        if n.compact in (*REQUIRED, *OPTIONAL):
            found.append(_Candidate(n.compact, i, 0, f"header names {n.compact}{unit}"))
        elif m := _FORCE.fullmatch(n.compact):
            key = "f" + (m.group(1) or m.group(2))
            found.append(_Candidate(key, i, 1, f"header names the load along "
                                               f"{key[1]} ({key}){unit}"))
        elif m := _OUTPUT.fullmatch(n.compact):
            key = "u" + (m.group(1) or m.group(2))
            found.append(_Candidate(key, i, 1, f"header names the output along "
                                               f"{key[1]} ({key}){unit}"))
        elif n.compact in _AXIS:
            found.append(_Candidate("axis", i, 1, "header names the loaded axis"))
        elif n.compact in _REPETITION:
            found.append(_Candidate("repetition", i, 1, "header names the repetition"))
        elif m := _CHANNEL.fullmatch(n.compact):
            families.setdefault(m.group(1), []).append((int(m.group(2)), i))
    for members in families.values():
        members.sort()
        start = members[0][0]
        if start not in (0, 1):
            continue
        # ch0..ch2 (or V1..V3): consecutive channels are the outputs in order (a
        # shorter run maps what it can, so the error names the output missing)
        run = [members[0]]
        for m in members[1:len(VOLTAGE_COLUMNS)]:
            if m[0] != run[-1][0] + 1:
                break
            run.append(m)
        span = f"{names[run[0][1]]}..{names[run[-1][1]]}"
        for key, (k, i) in zip(VOLTAGE_COLUMNS, run, strict=False):
            found.append(_Candidate(key, i, 2, f"numbered channel {k} of {span}, taken in "
                                               f"order as {', '.join(VOLTAGE_COLUMNS)}"))
    return found


def _unit_of(hint: str) -> str:
    return _LOAD_HINTS.get(hint) or _OUTPUT_HINTS[hint]


def _sniff_sep(first_line: str) -> str:
    counts = {s: len(next(csv.reader([first_line], delimiter=s), [])) for s in _SEPS}
    return max(_SEPS, key=lambda s: (counts[s], s == ","))  # a tie is a comma file


# --- the guess ---------------------------------------------------------------------


def guess_config(path: str | Path, *, max_rows: int = MAX_ROWS) -> Guess:
    """Guess a config for the calibration file ``path`` from its header and values.

    Raises :class:`~fsdecouple.errors.InputError` when the file cannot be read or a
    load or output column cannot be found (the message names the file, the missing
    quantity and the header seen).
    """
    path = Path(path)
    with reading(path), open(path, encoding="utf-8-sig", newline="") as fh:
        first = fh.readline(1 << 20)
        if not first.strip():
            raise InputError(f"{path}: no header row (the first line is empty)")
        sep = _sniff_sep(first)
        fh.seek(0)  # utf-8-sig drops the byte-order mark again
        reader = csv.reader(fh, delimiter=sep)
        names = [n.strip() for n in next(reader)]
        raw_rows = []
        truncated = False
        for row in reader:
            if len(raw_rows) >= max_rows:
                truncated = True
                break
            raw_rows.append(row)

    notes: list[str] = []
    ignored: dict[int, str] = {}
    # A side table (notes, a load plan) often sits right of the data after an
    # empty column: the data are the columns before the first unnamed one, if
    # every load and output is there.
    usable = list(range(len(names)))
    gap = next((i for i, n in enumerate(names) if not n), None)
    if gap is not None:
        left = {c.key for c in _candidates(names, list(range(gap)))}
        if set(REQUIRED) <= left:
            usable = list(range(gap))
            for i in range(gap + 1, len(names)):
                if names[i]:
                    ignored[i] = f"right of the unnamed column {gap + 1}: a side table"
        else:
            notes.append(f"column {gap + 1} has no name but the columns left of it do not "
                         "hold every load and output, so all columns were searched")
    for i, name in enumerate(names):
        if not name:
            ignored[i] = "no header name"
    seen: dict[str, list[int]] = {}
    for i in usable:
        seen.setdefault(names[i], []).append(i)
    for name, cols in seen.items():
        if name and len(cols) > 1:
            for i in cols:
                ignored[i] = ("header name repeated in columns "
                              f"{', '.join(str(c + 1) for c in cols)}")
    usable = [i for i in usable if i not in ignored]

    by_key: dict[str, list[_Candidate]] = {}
    for c in _candidates(names, usable):
        by_key.setdefault(c.key, []).append(c)
    columns: dict[str, int] = {}
    reasons: dict[str, str] = {}
    header_seen = ", ".join(_shown(n) for n in names)
    for key in KEYS:
        cands = sorted(by_key.get(key, []), key=lambda c: (c.rank, c.column))
        if not cands:
            if key in REQUIRED:
                what = "load" if key in FORCE_COLUMNS else "output"
                raise InputError(
                    f"{_comment(str(path))}: no column found for {key} (the {what} along "
                    f"{key[1]}); header: {_comment(header_seen)}; name it {key} or map it "
                    "under columns: in a config"
                )
            reasons[key] = (f"no {key} column: "
                            + ("sweeps are inferred from consecutive rows" if key == "axis"
                               else "one repetition in this file"))
            continue
        best = cands[0]
        columns[key] = best.column
        reasons[key] = f"{_shown(names[best.column])}: {best.why}"
        if len(cands) > 1:
            others = ", ".join(_shown(names[c.column]) for c in cands[1:])
            notes.append(f"{key}: more than one candidate; took {_shown(names[best.column])}, "
                         f"not {others}")
    for key, cands in by_key.items():
        for c in cands:
            if columns.get(key) != c.column and c.column not in ignored:
                ignored[c.column] = f"another candidate for {key}"
    for i in usable:
        if i not in columns.values() and i not in ignored:
            ignored[i] = "not a known quantity"

    # values: rows where every mapped cell is empty (a side table running past the
    # data, a blank line) are not data
    decimal = _sniff_decimal(sep, raw_rows, list(columns.values()))
    values: dict[str, list[float]] = {k: [] for k in columns}
    skipped: dict[str, int] = {k: 0 for k in columns}
    integers = True
    reps: set[str] = set()
    rows = 0
    for row in raw_rows:
        cells = {k: (row[i].strip() if i < len(row) else "") for k, i in columns.items()}
        if not any(cells.values()):
            continue
        rows += 1
        for key, text in cells.items():
            if key == "axis":
                continue
            if key == "repetition":
                if text:
                    reps.add(text)
                continue
            number = text.replace(decimal, ".") if decimal != "." else text
            if not _NUMBER.fullmatch(number):
                skipped[key] += 1
                continue
            values[key].append(float(number))
            if key in VOLTAGE_COLUMNS and not _INTEGER.fullmatch(number):
                integers = False
    if truncated:
        notes.append(f"read the first {max_rows:,} data rows only")
    for key in REQUIRED:
        if not values[key]:
            raise InputError(
                f"{_comment(str(path))}, column {_comment(_shown(names[columns[key]]))} "
                f"(taken as {key}): no numbers in {rows} data rows"
            )
        if skipped[key]:
            notes.append(f"{key}: {skipped[key]} cells of {_shown(names[columns[key]])} are "
                         "not numbers and were skipped")

    hints = {k: _parse_name(names[i]).hint for k, i in columns.items() if k in REQUIRED}
    peak_load = max(abs(v) for k in FORCE_COLUMNS for v in values[k])
    peak_out = max(abs(v) for k in VOLTAGE_COLUMNS for v in values[k])
    load, load_why = _load_unit(hints, peak_load, notes, names, columns)
    output, output_why = _output_unit(hints, peak_out, integers, notes, names, columns)
    reasons["units"] = f"load {load}: {load_why}; output {output}: {output_why}"

    full_scale: dict[str, float] = {}
    peaks = []
    for a, key in zip(AXES, FORCE_COLUMNS, strict=True):
        peak = max(abs(v) for v in values[key])
        peaks.append(f"{a} {peak:g}")
        if peak == 0:
            full_scale[a] = 1.0
            notes.append(f"full_scale {a}: no load along {a} in the data; 1 is a placeholder")
        else:
            full_scale[a] = nice_ceil(peak)
    reasons["full_scale"] = (f"largest |load| per axis ({', '.join(peaks)} {load}) rounded up "
                             "to a nice value (1, 2, 2.5 or 5 x 10^k)")

    if "repetition" in columns:
        min_repetitions = max(1, len(reps))
        reasons["min_repetitions"] = (f"{len(reps)} distinct values in "
                                      f"{_shown(names[columns['repetition']])}")
    else:
        min_repetitions = 1
        reasons["min_repetitions"] = "no repetition column: one repetition in this file"

    in_volts = output in ("V", "mV/V") and 0.1 <= peak_out <= 10
    scaling = "none" if in_volts else "full_scale"
    reasons["scaling"] = (
        f"outputs peak at {peak_out:g} {output}, of order 1 as Table 2's gamma assumes"
        if in_volts else
        f"outputs peak at {peak_out:g} {output}, not volts of order 1 as Table 2's gamma "
        "assumes: divide by each axis's full-scale output"
    )
    detected = "detected" if sep != "," else "the default"
    reasons["csv"] = (f"{detected}: {json.dumps(sep)}-separated"
                      + (", decimal comma" if decimal == "," else ""))

    return Guess(
        path=path, columns={k: names[i] for k, i in columns.items()},
        units={"load": load, "output": output}, full_scale=full_scale,
        min_repetitions=min_repetitions, scaling=scaling, sep=sep, decimal=decimal,
        reasons=reasons, ignored=[Ignored(i + 1, names[i], r) for i, r in sorted(ignored.items())],
        notes=notes, rows=rows,
    )


def _sniff_decimal(sep: str, rows: list[list[str]], cols: list[int]) -> str:
    if sep == ",":
        return "."  # a decimal comma cannot live in a comma-separated file
    comma = point = 0
    for row in rows[:1000]:
        for i in cols:
            cell = row[i].strip() if i < len(row) else ""
            comma += bool(re.fullmatch(r"[+-]?\d*,\d+(?:[eE][+-]?\d+)?", cell))
            point += bool(re.fullmatch(r"[+-]?\d*\.\d+(?:[eE][+-]?\d+)?", cell))
    # a ';' file is European unless its numbers say otherwise
    return "." if point > comma else ","


def _hinted(hints: dict[str, str | None], keys, table: dict[str, str], notes, names, columns,
            what: str) -> tuple[str | None, str]:
    found = {k: table[h] for k in keys if (h := hints.get(k)) in table}
    units = sorted(set(found.values()))
    if not units:
        return None, ""
    if len(units) > 1:
        notes.append(f"{what} headers disagree on the unit ({', '.join(units)}); took "
                     f"{found[next(iter(found))]}")
    unit = found[next(iter(found))]
    cols = ", ".join(_shown(names[columns[k]]) for k in found)
    return unit, f"header hint in {cols} ({_UNIT_NAMES[unit]})"


def _load_unit(hints, peak, notes, names, columns) -> tuple[str, str]:
    unit, why = _hinted(hints, FORCE_COLUMNS, _LOAD_HINTS, notes, names, columns, "load")
    if unit is not None:
        return unit, why
    if peak > GF_ABOVE:
        notes.append("load unit gf is a guess from the magnitudes (no unit in the headers)")
        return "gf", f"a guess: largest |load| {peak:g} > {GF_ABOVE:g}, no unit in the headers"
    notes.append("load unit N is a guess from the magnitudes (no unit in the headers)")
    return "N", f"a guess: largest |load| {peak:g} <= {GF_ABOVE:g}, no unit in the headers"


def _output_unit(hints, peak, integers, notes, names, columns) -> tuple[str, str]:
    unit, why = _hinted(hints, VOLTAGE_COLUMNS, _OUTPUT_HINTS, notes, names, columns, "output")
    if unit is not None:
        return unit, why
    if integers and peak > COUNT_ABOVE:
        return "count", f"every output an integer, largest |output| {peak:g} > {COUNT_ABOVE:g}"
    notes.append("output unit is a guess from the magnitudes (no unit in the headers)")
    if peak <= 20:
        return "V", f"a guess: largest |output| {peak:g} <= 20"
    if peak <= 20_000:
        return "mV", f"a guess: largest |output| {peak:g} in 20..20000"
    return "uV", f"a guess: largest |output| {peak:g} > 20000, not all integers"


def init_config(path: str | Path, output: str | Path, *, force: bool = False) -> Guess:
    """Guess a config for ``path`` and write it to ``output`` (atomically).

    An existing ``output`` is refused without ``force``, and always if it is ``path``.
    Nothing is written when the guess fails.
    """
    output = Path(output)
    check_output(output, force=force)
    refuse_overwriting_input(output, [path])
    guess = guess_config(path)
    with atomic_write(output, force=force) as fh:
        fh.write(guess.to_yaml())
    guess.config = output
    return guess


def guess_table(guess: Guess):
    """The rich table of the guesses (file text shown literally, never as markup)."""
    from rich.table import Table
    from rich.text import Text

    t = Table(title=Text(f"Guessed from {guess.path}"))
    for name in ("key", "column", "reason"):
        t.add_column(name)
    for key in KEYS:
        col = guess.columns.get(key)
        t.add_row(key, Text(col if col is not None else "-"), Text(guess.reasons[key]))
    t.add_row("units", Text(f"load: {guess.units['load']}, output: {guess.units['output']}"),
              Text(guess.reasons["units"]))
    t.add_row("full_scale", Text(", ".join(f"{a}: {_num(v)}" for a, v in guess.full_scale.items())),
              Text(guess.reasons["full_scale"]))
    t.add_row("min_repetitions", str(guess.min_repetitions), Text(guess.reasons["min_repetitions"]))
    t.add_row("csv", Text(f"sep {guess.sep!r}, decimal {guess.decimal!r}"), Text(guess.reasons["csv"]))
    t.add_row("scaling", guess.scaling, Text(guess.reasons["scaling"]))
    for i in guess.ignored:
        t.add_row("(ignored)", Text(f"{i.column}: {_shown(i.name)}"), Text(i.reason))
    return t
