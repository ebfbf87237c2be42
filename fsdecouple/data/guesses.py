"""Starting a config from a calibration file (``fsdecouple init``).

One CSV's header and values (at most :data:`MAX_ROWS` rows) give guesses of the
columns, units, full scale and scaling, each with its reason: a guess nobody can
check is worse than none.  Reading is lenient on purpose (unnamed and repeated
header names, side tables, text in number columns); ``ingest`` validates.
"""

from __future__ import annotations

import collections
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import yaml

from ..axes import AXES, FORCE_COLUMNS, VOLTAGE_COLUMNS
from ..errors import InputError
from ..units import MOMENT_UNITS, unit_key
from .csv_text import read_rows
from .magnitudes import adc_bits, full_scale_of, full_scale_reason, nice_ceil  # noqa: F401

MAX_ROWS = 100_000  # enough for any calibration; bounds a wrong file's cost

REQUIRED = (*FORCE_COLUMNS, *VOLTAGE_COLUMNS)
OPTIONAL = ("axis", "repetition")
KEYS = (*OPTIONAL[::-1], *REQUIRED)  # the order the config lists them

# unit words as they appear in headers ([gf], (kgf), _N, lbf), lower case
LOAD_HINTS = {"n": "N", "kn": "kN", "gf": "gf", "g": "gf", "kgf": "kgf", "kg": "kgf",
               "lbf": "lbf", "lb": "lbf", "lbs": "lbf"}
_OUTPUT_HINTS = {"v": "V", "mv": "mV", "uv": "uV", "µv": "uV", "μv": "uV", "count": "count",
                 "counts": "count", "cnt": "count", "lsb": "count", "mv/v": "mV/V",
                 "mvv": "mV/V", "mv/v excitation": "mV/V"}
_HINTS = {**LOAD_HINTS, **_OUTPUT_HINTS}
_MOMENT_WORDS = {unit_key(u) for u in MOMENT_UNITS}
_UNIT_NAMES = {"N": "newton", "kN": "kilonewton", "gf": "gram-force", "kgf": "kilogram-force",
               "lbf": "pound-force", "V": "volt", "mV": "millivolt", "uV": "microvolt",
               "count": "ADC counts", "mV/V": "millivolt per volt of excitation"}

# names after units and separators are stripped (`Force_X [N]` -> "forcex")
_FORCE = re.compile(r"(?:f|force|load|applied|appliedforce|appliedload|standardload)([xyz])"
                    r"|([xyz])(?:force|load)")
_OUTPUT = re.compile(r"(?:u|v|volt|volts|voltage|sensor|out|output|signal|bridge|sg|strain)"
                     r"([xyz])|([xyz])(?:volt|voltage|output|signal|sensor)")
_CHANNEL = re.compile(r"(ch|chan|channel|adc|ain|ai|v)(\d+)")
AXIS_HEADERS = {"axis", "loadaxis", "loadedaxis", "direction", "loaddirection"}
REPETITION_HEADERS = {"repetition", "rep", "repeat", "run", "cycle", "trial", "repno", "repetitionno"}

NUMBER = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?")
INTEGER = re.compile(r"[+-]?\d+")

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
    keys: tuple[str, ...] = KEYS  # the columns: entries, in config order
    components: tuple[str, ...] = ()  # a sensor with named components (guess_layout.py)
    outputs: tuple[str, ...] = ()
    load_units: dict[str, str] | None = None  # per component, where they differ
    output_units: dict[str, str] | None = None  # per output, where they differ
    zero: str | None = None  # "intercept" for data without an unloaded row (data/zero.py)
    gamma: float | None = None  # svr: gamma for poses of a mass (init_config.POSE_GAMMA)
    method: str | None = None  # "auto" for poses of a mass (init_config.POSE_METHOD)

    def to_dict(self) -> dict[str, Any]:
        """The ``--json`` document."""
        return {
            "config": None if self.config is None else str(self.config), "data": str(self.path),
            "columns": dict(self.columns), "units": dict(self.units),
            "full_scale": dict(self.full_scale), "min_repetitions": self.min_repetitions,
            "scaling": self.scaling, "csv": {"sep": self.sep, "decimal": self.decimal},
            "rows": self.rows, "reasons": dict(self.reasons), "notes": list(self.notes),
            "ignored": [i.name for i in self.ignored],
            "ignored_columns": [vars(i) for i in self.ignored],
            **({"components": list(self.components), "outputs": list(self.outputs),
                "load_units": self.load_units, "output_units": self.output_units}
               if self.components else {}),
            **({"zero": self.zero} if self.zero else {}),
            **({"svr": {"gamma": self.gamma}} if self.gamma else {}),
            **({"method": self.method} if self.method else {}),
        }

    def settings(self) -> list[tuple[str, str, str]]:
        """(key, YAML flow value, reason) of each guessed setting, in config order."""
        fs = ", ".join(f"{a}: {_num(v)}" for a, v in self.full_scale.items())
        load = self.units["load"] if not self.load_units else \
            "{" + ", ".join(f"{c}: {u}" for c, u in self.load_units.items()) + "}"
        output = self.units["output"] if not self.output_units else \
            "{" + ", ".join(f"{o}: {u}" for o, u in self.output_units.items()) + "}"
        temp = f", temperature: {self.units['temperature']}" if "temperature" in self.units else ""
        values = {
            **({"components": f"[{', '.join(self.components)}]",
                "outputs": f"[{', '.join(self.outputs)}]"} if self.components else {}),
            "units": f"{{load: {load}, output: {output}{temp}}}",
            "full_scale": f"{{{fs}}}", "min_repetitions": str(self.min_repetitions),
            "csv": f"{{sep: {json.dumps(self.sep)}, decimal: {json.dumps(self.decimal)}}}",
            "scaling": self.scaling,
            **({"zero": self.zero} if self.zero else {}),
            **({"svr": f"{{gamma: {self.gamma!r}}}"} if self.gamma else {}),
            **({"method": self.method} if self.method else {}),
        }
        return [(k, v, self.reasons[k]) for k, v in values.items()]

    def to_yaml(self) -> str:
        """The commented config: every guessed value with a comment saying why."""
        out = [
            f"# Started by `fsdecouple init` from {one_line(str(self.path))}",
            f"# ({self.rows} data rows read). Values marked 'guessed' come from the header",
            "# and the magnitudes of the data: check each one before fitting.",
            "",
            "# Any name; taken from the data file's name.",
            f"sensor: {_scalar(self.path.stem or 'sensor')}",
            "",
            "# File column for each quantity.",
            "columns:",
        ]
        for key in self.keys:
            if key in self.columns:
                out.append(f"  {key}: {_scalar(self.columns[key])}"
                           f"   # guessed: {one_line(self.reasons[key])}")
            else:
                out.append(f"  # {key}: not mapped ({one_line(self.reasons[key])})")
        if self.ignored:
            out.append("# Ignored columns (not read):")
            out += [f"#   column {i.column} {one_line(shown(i.name))}: {one_line(i.reason)}"
                    for i in self.ignored]
        for key, value, why in self.settings():
            out += ["", f"# {'' if key == 'csv' else 'guessed: '}{one_line(why)}",
                    f"{key}: {value}"]
        if self.notes:
            out += ["", "# Notes:"] + [f"#   {one_line(n)}" for n in self.notes]
        return "\n".join(out) + "\n"


def _scalar(value: str) -> str:
    """``value`` as a YAML scalar that reads back as the same string."""
    text = yaml.safe_dump([value], default_flow_style=True, width=1 << 30, allow_unicode=True)
    return text.strip()[1:-1]


def one_line(text: str) -> str:
    """Text that stays on one comment line (a header may hold a line break)."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def shown(name: str) -> str:
    return f"'{name}'" if name else "(no name)"


def _num(v: float) -> str:
    return str(int(v)) if float(v).is_integer() else repr(float(v))


def parse_name(header: str) -> tuple[str, str | None]:
    """(name in lower case without units and separators, unit word found or None)."""
    text = header.strip().lower()
    hints = re.findall(r"[\[(]([^\])]*)[\])]", text)
    text = re.sub(r"[\[(][^\])]*[\])]", " ", text)
    tokens = [t for t in re.split(r"[\s_\-]+", text.strip()) if t]
    if len(tokens) > 1 and (tokens[-1] in _HINTS or unit_key(tokens[-1]) in _MOMENT_WORDS):
        hints.append(tokens.pop())  # Fx_gf, Mx_Nm: a unit after the name
    hint = next((h.strip() for h in hints if h.strip() in _HINTS), None)
    return re.sub(r"[^0-9a-zµμ]", "", "".join(tokens)), hint


class _Candidate(NamedTuple):
    key: str
    column: int  # 0-based
    rank: int  # 0 the config's own name, 1 a named pattern, 2 a numbered channel
    why: str


def _candidates(names: list[str], usable: list[int]) -> list[_Candidate]:
    found: list[_Candidate] = []
    families: dict[str, list[tuple[int, int]]] = {}
    for i in usable:
        name, hint = parse_name(names[i])
        unit = f", unit {hint} ({_UNIT_NAMES[_HINTS[hint]]})" if hint else ""
        if name in (*REQUIRED, *OPTIONAL):
            found.append(_Candidate(name, i, 0, f"header names {name}{unit}"))
        elif m := _FORCE.fullmatch(name):
            key = "f" + (m.group(1) or m.group(2))
            found.append(_Candidate(key, i, 1, f"header names the load along "
                                               f"{key[1]} ({key}){unit}"))
        elif m := _OUTPUT.fullmatch(name):
            key = "u" + (m.group(1) or m.group(2))
            found.append(_Candidate(key, i, 1, f"header names the output along "
                                               f"{key[1]} ({key}){unit}"))
        elif name in AXIS_HEADERS:
            found.append(_Candidate("axis", i, 1, "header names the loaded axis"))
        elif name in REPETITION_HEADERS:
            found.append(_Candidate("repetition", i, 1, "header names the repetition"))
        elif m := _CHANNEL.fullmatch(name):
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


_APPLIED = re.compile(r"(?:known|applied|reference|ref|true|nominal)[a-z]+\d*"
                      r"|[a-z]+\d*(?:ref|reference|applied|known)")


def applied_load(header: str) -> bool:
    """Whether ``header`` names an applied (reference) load: ``known_Fx``, ``Fz_ref [N]``."""
    return bool(_APPLIED.fullmatch(parse_name(header)[0]))


# --- the guess ---------------------------------------------------------------------


def guess_config(path: str | Path, *, max_rows: int = MAX_ROWS) -> Guess:
    """Guess a config for the calibration file ``path`` from its header and values.

    Raises :class:`~fsdecouple.errors.InputError` when the file cannot be read or a
    load or output column cannot be found (the message names the file, the missing
    quantity and the header seen).
    """
    path = Path(path)
    return guess_rows(path, *read_rows(path, max_rows))


def guess_rows(path: Path, names: list[str], raw_rows: list[list[str]], sep: str,
               truncated: bool) -> Guess:
    """:func:`guess_config` of a file already read by :func:`read_rows`."""
    notes: list[str] = []
    ignored: dict[int, str] = {}
    # A side table (notes, a load plan) often sits right of the data after an
    # empty column: the data are the columns before the first unnamed one, if
    # every load and output is there.
    usable = list(range(len(names)))
    gap = next((i for i, n in enumerate(names) if not n), None)
    if gap is not None and set(REQUIRED) <= {c.key for c in _candidates(names, usable[:gap])}:
        usable = usable[:gap]
        ignored.update({i: f"right of the unnamed column {gap + 1}: a side table"
                        for i in range(gap + 1, len(names)) if names[i]})
    elif gap is not None:
        notes.append(f"column {gap + 1} has no name but the columns left of it do not "
                     "hold every load and output, so all columns were searched")
    ignored.update({i: "no header name" for i, name in enumerate(names) if not name})
    count = collections.Counter(names[i] for i in usable)
    ignored.update({i: f"header name repeated ({count[names[i]]} columns)"
                    for i in usable if names[i] and count[names[i]] > 1})
    usable = [i for i in usable if i not in ignored]

    by_key: dict[str, list[_Candidate]] = {}
    for c in _candidates(names, usable):
        by_key.setdefault(c.key, []).append(c)
    columns: dict[str, int] = {}
    reasons: dict[str, str] = {}
    header_seen = ", ".join(shown(n) for n in names)
    for key in KEYS:
        cands = sorted(by_key.get(key, []), key=lambda c: (c.rank, c.column))
        if not cands:
            if key in REQUIRED:
                what = "load" if key in FORCE_COLUMNS else "output"
                raise InputError(
                    f"{one_line(str(path))}: no column found for {key} (the {what} along "
                    f"{key[1]}); header: {one_line(header_seen)}; name it {key} or map it "
                    "under columns: in a config"
                )
            reasons[key] = f"no {key} column: " + (
                "sweeps are inferred from consecutive rows" if key == "axis" else "one repetition")
            continue
        best = cands[0]
        columns[key] = best.column
        reasons[key] = f"{shown(names[best.column])}: {best.why}"
        if len(cands) > 1:
            others = ", ".join(shown(names[c.column]) for c in cands[1:])
            notes.append(f"{key}: more than one candidate; took {shown(names[best.column])}, "
                         f"not {others}")
    for c in (c for cands in by_key.values() for c in cands):
        if columns[c.key] != c.column:
            ignored[c.column] = f"another candidate for {c.key}"
    for i in set(usable) - set(columns.values()) - set(ignored):
        ignored[i] = "not a known quantity"

    # values: rows where every mapped cell is empty (a side table running past the
    # data, a blank line) are not data
    decimal = sniff_decimal(sep, raw_rows, list(columns.values()))
    values: dict[str, list[float]] = {k: [] for k in REQUIRED}
    skipped = dict.fromkeys(REQUIRED, 0)
    integers, reps, rows = True, set(), 0
    for row in raw_rows:
        cells = {k: (row[i].strip() if i < len(row) else "") for k, i in columns.items()}
        rows += any(cells.values())
        reps.add(cells.get("repetition", ""))
        for key in REQUIRED if any(cells.values()) else ():
            number = cells[key].replace(decimal, ".")
            if not NUMBER.fullmatch(number) or not math.isfinite(float(number)):  # 1e400: inf
                skipped[key] += 1
                continue
            values[key].append(float(number))
            integers &= key in FORCE_COLUMNS or bool(INTEGER.fullmatch(number))
    reps.discard("")
    if truncated:
        notes.append(f"read the first {len(raw_rows):,} data rows only")
    for key in REQUIRED:
        if not values[key]:
            raise InputError(
                f"{one_line(str(path))}, column {one_line(shown(names[columns[key]]))} "
                f"(taken as {key}): no numbers in {rows} data rows"
            )
        if skipped[key]:
            notes.append(f"{key}: {skipped[key]} cells of {shown(names[columns[key]])} are "
                         "not numbers and were skipped")

    hints = {k: parse_name(names[i])[1] for k, i in columns.items()}
    labels = {k: shown(names[i]) for k, i in columns.items()}
    peak_load = max(abs(v) for k in FORCE_COLUMNS for v in values[k])
    peak_out = max(abs(v) for k in VOLTAGE_COLUMNS for v in values[k])
    load, load_why = guess_unit("load", hints, peak_load, integers, notes, labels)
    bits = adc_bits([v for k in VOLTAGE_COLUMNS for v in values[k]]) if integers else None
    output, output_why = guess_unit("output", hints, peak_out, integers, notes, labels, bits=bits)
    reasons["units"] = f"load {load}: {load_why}; output {output}: {output_why}"

    peaks = {a: max(abs(v) for v in values[k]) for a, k in zip(AXES, FORCE_COLUMNS, strict=True)}
    full_scale = {a: full_scale_of(p) if p else 1.0 for a, p in peaks.items()}
    notes += [f"full_scale {a}: no load along {a} in the data; 1 is a placeholder"
              for a, p in peaks.items() if not p]
    reasons["full_scale"] = full_scale_reason(peaks, dict.fromkeys(peaks, load))
    min_repetitions = max(1, len(reps))
    reasons["min_repetitions"] = (f"{len(reps)} distinct values in {labels['repetition']}"
                                  if "repetition" in columns else
                                  "no repetition column: one repetition in this file")

    in_volts = output in ("V", "mV/V") and 0.1 <= peak_out <= 10
    scaling = "none" if in_volts else "full_scale"
    reasons["scaling"] = (
        f"outputs peak at {peak_out:g} {output}, of order 1 as Table 2's gamma assumes"
        if in_volts else
        f"outputs peak at {peak_out:g} {output}, not volts of order 1 as Table 2's gamma "
        "assumes: divide by each axis's full-scale output"
    )
    reasons["csv"] = (f"{'the default' if sep == ',' else 'detected'}: {json.dumps(sep)}-"
                      f"separated{', decimal comma' if decimal == ',' else ''}")

    return Guess(
        path=path, columns={k: names[i] for k, i in columns.items()},
        units={"load": load, "output": output}, full_scale=full_scale,
        min_repetitions=min_repetitions, scaling=scaling, sep=sep, decimal=decimal,
        reasons=reasons, ignored=[Ignored(i + 1, names[i], r) for i, r in sorted(ignored.items())],
        notes=notes, rows=rows,
    )


_POINT = re.compile(r"[+-]?\d*\.\d+([eE][+-]?\d+)?")
_COMMA = re.compile(r"[+-]?\d*,\d+([eE][+-]?\d+)?")


def sniff_decimal(sep: str, rows: list[list[str]], cols: list[int]) -> str:
    """'.' in a comma file; else ',' (European) unless its numbers say otherwise."""
    if sep == ",":
        return "."
    cells = [row[i].strip() for row in rows[:1000] for i in cols if i < len(row)]
    point = sum(bool(_POINT.fullmatch(c)) for c in cells)
    comma = sum(bool(_COMMA.fullmatch(c)) for c in cells)
    return "." if point > comma else ","


def guess_unit(kind: str, hints: dict[str, str | None], peak: float, integers: bool,
          notes: list[str], shown: dict[str, str], keys=None,
          bits: int | None = None) -> tuple[str, str]:
    """The ``load`` or ``output`` unit: from header hints, else from the magnitudes.

    ``keys``: the columns to look at (default: fx, fy, fz or ux, uy, uz).
    """
    default, table = ((FORCE_COLUMNS, LOAD_HINTS) if kind == "load"
                      else (VOLTAGE_COLUMNS, _OUTPUT_HINTS))
    keys = default if keys is None else keys
    found = {k: table[h] for k in keys if (h := hints.get(k)) in table}
    if found:
        unit = next(iter(found.values()))
        if len(set(found.values())) > 1:
            notes.append(f"{kind} headers disagree on the unit "
                         f"({', '.join(sorted(set(found.values())))}); took {unit}")
        return unit, f"header hint in {', '.join(shown[k] for k in found)} ({_UNIT_NAMES[unit]})"
    if kind == "output" and integers and bits is not None:
        return "count", (f"every output a whole number within 0 .. {2 ** bits - 1} (a {bits}-bit "
                         "ADC's raw counts)")
    if kind == "output" and integers and peak > COUNT_ABOVE:
        return "count", f"every output an integer, largest |output| {peak:g} > {COUNT_ABOVE:g}"
    if kind == "load":
        unit, why = ("gf", f"> {GF_ABOVE:g}") if peak > GF_ABOVE else ("N", f"<= {GF_ABOVE:g}")
    else:
        unit, why = next((u, f"<= {top:g}") for u, top in
                         (("V", 20), ("mV", 20_000), ("uV", math.inf)) if peak <= top)
    notes.append(f"{kind} unit {unit} is a guess from the magnitudes (no unit in the headers)")
    return unit, f"a guess: largest |{kind}| {peak:g} {why}, no unit in the headers"
