"""``fsdecouple init`` for any sensor: three axes (:mod:`fsdecouple.data.guesses`) or N components.

A header that names a moment (``Mx``, ``Tz [N·mm]``, ``torque_y`` ...) is a
force/torque sensor.  Its load columns become ``components`` (fx, fy, fz, mx,
my, mz: those present, in that order), one family of numbered channels
(``u1 .. u6``, ``ch0 .. ch5``, ``sg1 ..``) the outputs, and each component's
prime output (eq. 1: the output its own load drives, u_aa) is the channel that
component's single-load rows move most, relative to the channel's whole span:
about 1 for the prime output, the coupling fraction for the others.  Units,
full scales and scaling are guessed as for three axes, the load unit per
component (forces and moments differ).  Every guess comes with its reason.
"""

from __future__ import annotations

import math
import re
import tempfile
from pathlib import Path

import numpy as np

from ..axes import FORCE_COLUMNS
from ..config import load_config
from ..errors import ConfigError, InputError, printable
from ..files.outputs import atomic_write, check_output, refuse_overwriting_input
from ..units import LOAD_UNITS, MOMENT_UNITS, unit_key
from .csv_text import first_difference
from .guesses import (
    AXIS_HEADERS,
    INTEGER,
    LOAD_HINTS,
    MAX_ROWS,
    NUMBER,
    REPETITION_HEADERS,
    Guess,
    Ignored,
    adc_bits,
    full_scale_of,
    full_scale_reason,
    guess_rows,
    guess_unit,
    one_line,
    parse_name,
    read_rows,
    shown,
    sniff_decimal,
)
from .poses import TIMESTAMP_NAMES
from .temperature_column import with_temperature

COMPONENTS = ("fx", "fy", "fz", "mx", "my", "mz")
# Poses of a known mass (issue 32): no row unloaded and POSE_SHARE of the rows loading
# POSE_LOADS components or more (a weight has three force components; a lever arm's rows
# two).  Their SVRs get gamma POSE_GAMMA, a kernel sqrt(5) x Table 2's width: on simulated
# eight-gauge pose sets (sim/poses.py, seeds 0-9, held out by pose in 5 folds) Table 2's
# 0.5 gave the worst component 0.4-1.2 x the error of a least-squares matrix with offset;
# 0.1 gave 0.2-0.9 x, 0.2 about the same, 0.03 0.9-1.9 x (too stiff for C = 1).
POSE_SHARE = 0.9
POSE_LOADS = 3
POSE_GAMMA = 0.1
# ... and they decouple by whichever of the coupling error model and the least-squares
# matrix (with its offset) has the lower held-out error, poses held out in 5 folds
# (evaluation/heldout.py): on the public eight-gauge set (60 poses, 10-bit counts) the
# model held out at 1.07-1.32 x the matrix's worst component for gamma 1 .. 0.03 (1.17 x at
# POSE_GAMMA), on the simulated sets at 0.2-0.9 x; the verdict tells them apart on the set
# at hand.
POSE_METHOD = "auto"
_LOAD = re.compile(r"(?:f|force|load)([xyz])|([xyz])(?:force|load)")
_MOMENT = re.compile(r"(?:m|t|moment|torque)([xyz])|([xyz])(?:moment|torque)")
_NUMBERED = re.compile(r"([a-zµμ]+)(\d+)")
# an applied (reference) load: a component's name after or before one of these words
_APPLIED = re.compile(r"(?:known|applied|reference|ref|true|load|nominal)(\w+)"
                      r"|(\w+?)(?:ref|reference|applied|known|true)")
_TIMESTAMP = TIMESTAMP_NAMES  # poses.py: a timestamp column makes a file a pose log
_MOMENT_HINTS = {u.lower(): u for u in MOMENT_UNITS}
# any other spelling of a known unit (N mm, n*m, KGF.CM): the first of its spellings
_SPELLED = {}
for _u in (*MOMENT_UNITS, *LOAD_UNITS):
    _SPELLED.setdefault(unit_key(_u), _u)
_BRACKETS = re.compile(r"[\[(]([^\])]*)[\])]")


def _component(header: str) -> str | None:
    """fx .. mz when ``header`` names a force or moment component, else None."""
    name, _ = parse_name(header)
    if m := _MOMENT.fullmatch(name):
        return "m" + (m.group(1) or m.group(2))
    if m := _LOAD.fullmatch(name):
        return "f" + (m.group(1) or m.group(2))
    return None


def _applied(header: str) -> str | None:
    """fx .. mz when ``header`` names an applied load (``known_Fx``, ``Fz_ref [N]``), else None."""
    name, _ = parse_name(header)
    if m := _APPLIED.fullmatch(name):
        return _component(m.group(1) or m.group(2))
    return None


def init_config(path: str | Path, output: str | Path, *, force: bool = False) -> Guess:
    """Guess a config for ``path`` (three axes, or components) and write it to ``output``.

    An existing ``output`` is refused without ``force``, and always if it is ``path``.
    Nothing is written when the guess fails.
    """
    output = Path(output)
    check_output(output, force=force)
    refuse_overwriting_input(output, [path])
    guess = guess_layout(path)
    text = guess.to_yaml()
    _check_loads(text, path)
    with atomic_write(output, force=force) as fh:
        fh.write(text)
    guess.config = output
    return guess


def _check_loads(text: str, data: str | Path) -> None:
    """Refuse a guessed config that ``load_config`` would refuse (a full scale of 1e300,
    two channels with one key): better one line now than a config that cannot be read."""
    with tempfile.TemporaryDirectory(prefix="fsdecouple-init-") as tmp:
        trial = Path(tmp) / "guessed.yaml"
        trial.write_text(text, encoding="utf-8")
        try:
            load_config(trial)
        except ConfigError as err:
            reason = str(err).removeprefix(f"{printable(trial)}")
            raise InputError(f"{one_line(str(data))}: the guessed config would not load"
                             f"{reason}; check the data, or write the config by hand") from None


def guess_layout(path: str | Path, *, max_rows: int = MAX_ROWS) -> Guess:
    """:func:`guess_components` when the header names a moment or a rig's applied loads beside
    the readings, else the 3-axis guess."""
    path = Path(path)
    sizes: list[int] = []  # a directory's: the rows read of each file
    files = 1
    if path.is_dir():
        names, rows, sep, truncated, files = _directory_rows(path, max_rows, sizes)
    else:
        names, rows, sep, truncated = read_rows(path, max_rows)
    # a moment, or applied loads named as such beside readings named like the components
    # (Fx_ref and Fx: a rig's reference and the sensor's own reading) take the component path
    rig = any(_applied(n) for n in names) and any(_component(n) and not _applied(n) for n in names)
    if not rig and not any((_component(n) or _applied(n) or " ")[0] == "m" for n in names):
        guess = guess_rows(path, names, rows, sep, truncated)
    else:
        try:
            guess = guess_components(path, names, rows, sep, truncated)
        except InputError as err:  # a 3-axis file with moment columns beside it reads as before
            try:
                guess = guess_rows(path, names, rows, sep, truncated)
            except InputError:
                raise err from None
    return with_temperature(_files_as_repetitions(guess, names, rows, sizes, files), names)


def _files_as_repetitions(guess: Guess, names: list[str], rows: list[list[str]],
                          sizes: list[int], files: int) -> Guess:
    """A directory's ``files`` are read one repetition a file, as ``fit`` reads them (a
    repetition column counts in a single file only), unless each file read holds one
    pose (one load: a pose directory, all one calibration).  ``sizes``: the rows read
    of each file, in order (the first files only, where the read was cut)."""
    loads = [names.index(guess.columns[c]) for c in (guess.components or FORCE_COLUMNS)
             if c in guess.columns]
    starts = np.cumsum([0, *sizes])
    if files < 2 or all(len({tuple(r[i] for i in loads) for r in rows[a:b]}) <= 1
                        for a, b in zip(starts[:-1], starts[1:], strict=True)):
        return guess
    guess.min_repetitions = files
    why = ("a repetition column counts in a single file only" if "repetition" in guess.columns
           else "no repetition column")
    guess.reasons["repetition"] = f"{why}: one repetition a file"
    guess.reasons["min_repetitions"] = f"{why}: each of the {files} files is one repetition"
    return guess


def _directory_rows(path: Path, max_rows: int, sizes: list[int]
                    ) -> tuple[list[str], list[list[str]], str, bool, int]:
    """The rows of a directory's CSV files (a pose directory: one pose a file), joined under
    their one header, and how many files it has: every file's rows count for the loads,
    the zero rule and full scale.  Files in another layout are refused by name, as fit
    refuses them.  ``sizes`` gets each file's number of rows read, in order."""
    from .calibration_csv import list_calibration

    files, _ = list_calibration(path)
    names, rows, sep, truncated = read_rows(files[0], max_rows)
    sizes.append(len(rows))
    for f in files[1:]:
        if len(rows) >= max_rows:
            truncated = True
            break
        other, more, _, cut = read_rows(f, max_rows - len(rows))
        sizes.append(len(more))
        if other != names:
            j, found, want = first_difference(other, names)
            raise InputError(f"{one_line(str(f))}, row 1: column {j + 1} is {one_line(found)}, "
                             f"{one_line(files[0].name)} has {one_line(want)} there; the files "
                             "of a calibration directory share one layout")
        rows += more
        truncated |= cut
    return names, rows, sep, truncated, len(files)


def guess_components(path: Path, names: list[str], rows: list[list[str]], sep: str,
                     truncated: bool) -> Guess:
    """The config of a force/torque file: components, their prime outputs, units, full scales."""
    where = one_line(str(path))
    header = one_line(", ".join(shown(n) for n in names))
    count = {n: names.count(n) for n in names}
    ignored = {i: ("no header name" if not n else f"header name repeated ({count[n]} columns)")
               for i, n in enumerate(names) if not n or count[n] > 1}
    usable = [i for i in range(len(names)) if i not in ignored]
    # applied loads named as such (known_Fx, Fz_ref) make the plain component names
    # (Fx .. Mz) the sensor's own readings: its outputs
    applied = {i: _applied(names[i]) for i in usable}
    named_as = _applied if any(applied.values()) else _component
    loads: dict[str, int] = {}
    for i in usable:
        key = named_as(names[i])
        if key and key not in loads:
            loads[key] = i
    components = tuple(c for c in COMPONENTS if c in loads)
    parsed = {i: parse_name(names[i])[0] for i in usable}
    special: dict[int, str] = {}  # the first axis and repetition column
    for i in usable:
        key = ("axis" if parsed[i] in AXIS_HEADERS
               else "repetition" if parsed[i] in REPETITION_HEADERS else None)
        if key and key not in special.values():
            special[i] = key
    stamps = [i for i in usable if parsed[i] in _TIMESTAMP and i not in special]
    readings = {}
    if named_as is _applied:
        for i in usable:
            key = _component(names[i])
            if key in components and key not in readings and i not in loads.values():
                readings[key] = i
    families: dict[str, list[tuple[int, int]]] = {}
    for i in usable:
        if i not in loads.values() and i not in special and (m := _NUMBERED.fullmatch(parsed[i])):
            families.setdefault(m.group(1), []).append((int(m.group(2)), i))
    if len(readings) == len(components):  # the readings, named: one family, in component order
        families = {"": [(k, readings[c]) for k, c in enumerate(components)]}
    fits = [sorted(f) for f in families.values() if len(f) == len(components)]
    if len(components) < 2:
        raise InputError(f"{where}: the header names {len(components)} load component "
                         f"({', '.join(components)}); a coupling model needs at least 2; header: {header}")
    more = [sorted(f) for f in families.values() if len(f) > len(components)]
    gauges = not fits and len(more) == 1  # M > N: every channel kept (fitting/gauges.py)
    if gauges:
        fits = more
    if len(fits) != 1:
        raise InputError(
            f"{where}: a force/torque header needs one numbered output channel per load "
            f"component ({len(components)}: {', '.join(components)}), e.g. u1..u{len(components)} "
            f"or ch0..ch{len(components) - 1}; found {len(fits)} such families; header: {header}")
    channels = [i for _, i in fits[0]]
    mapped = [loads[c] for c in components] + channels
    decimal = sniff_decimal(sep, rows, mapped)
    table = _numbers(rows, mapped, decimal)
    if len(table) == 0:
        raise InputError(f"{where}: no row holds a number in every load and output column")
    f, u = table[:, :len(components)], table[:, len(components):]
    notes: list[str] = [f"read the first {len(rows):,} data rows only"] if truncated else []
    if (left := sum(any(c.strip() for c in row) for row in rows) - len(table)) > 0:
        notes.append(f"{left} {'rows' if left > 1 else 'row'} without a finite number in every "
                     f"load and output column {'were' if left > 1 else 'was'} left out")
    if gauges:
        notes.append(f"{len(channels)} output channels for {len(components)} components (M > N): "
                     "fit models every channel and decouples in the least-squares sense")
        prime, why = list(range(len(channels))), {}
    else:
        prime, why = _pair(f, u, components, [names[i] for i in channels], notes,
                           named=len(readings) == len(components))
    outputs = tuple(parsed[channels[j]] + ("_out" if named_as is _applied and readings else "")
                    for j in prime)
    if len({o.lower() for o in outputs}) < len(outputs):
        same = ", ".join(shown(names[i]) for i in channels)
        raise InputError(f"{where}: output channels {same} do not have one name each once units "
                         "and separators are dropped; rename them, or write the config by hand")
    columns = {**{k: names[i] for i, k in special.items()},
               **{c: names[loads[c]] for c in components},
               **{o: names[channels[j]] for o, j in zip(outputs, prime, strict=True)}}
    reasons = {k: f"{shown(names[i])}: header names the {k}" for i, k in special.items()}
    reasons.update({c: f"{shown(names[loads[c]])}: header names the "
                    f"{'moment about' if c[0] == 'm' else 'force along'} {c[1]} ({c})"
                    for c in components})
    if gauges:
        reasons.update({o: f"{shown(columns[o])}: output channel {j + 1} of {len(outputs)}, no "
                        "component's own" for j, o in enumerate(outputs)})
    else:
        reasons.update({o: f"{shown(columns[o])}: {why[c]}"
                        for c, o in zip(components, outputs, strict=True)})
    for key in ("axis", "repetition"):
        reasons.setdefault(key, f"no {key} column: " + (
            "sweeps are inferred from consecutive rows" if key == "axis" else "one repetition"))
    reasons["components"] = "load columns found in the header, forces then moments"
    reasons["outputs"] = ("every output channel, in header order (more than components)" if gauges
                          else "the prime output of each component, in the same order")
    load_units = _load_units(names, loads, components, f, notes)
    integers = all(INTEGER.fullmatch(row[i].strip()) for row in rows[:1000] for i in channels
                   if i < len(row) and NUMBER.fullmatch(row[i].strip()))
    peak_out = float(np.abs(u).max())
    hints = {f"c{j}": parse_name(names[i])[1] for j, i in enumerate(channels)}
    out_units = None
    if named_as is _applied and len(readings) == len(components):
        # a sensor's own readings named like its components are factory-calibrated
        # forces and moments: in load units (their header's, else their component's)
        out_units = {o: header_unit(names[channels[j]], c[0] == "m")[0] or load_units[c]
                     for o, j, c in zip(outputs, prime, components, strict=True)}
        out_unit = next(iter(out_units.values())) if len(set(out_units.values())) == 1 else "mixed"
        out_why = ("the sensor's own readings, named like the components (factory-calibrated "
                   "forces and moments): each reading's header unit, else its component's")
        out_units = out_units if out_unit == "mixed" else None
    else:
        out_unit, out_why = guess_unit("output", hints, peak_out, integers, notes,
                                  {f"c{j}": shown(names[i]) for j, i in enumerate(channels)},
                                  keys=list(hints), bits=adc_bits(u) if integers else None)
    bits = adc_bits(u) if out_unit == "count" and integers else None
    if bits is not None:  # a misread (459 read as 4598) is no peak of a k-bit ADC's readings
        peak_out = float(np.abs(u[u <= 2 ** bits - 1]).max())
    mixed = len(set(load_units.values())) > 1
    shown_out = ", ".join(f"{o} {v}" for o, v in out_units.items()) if out_units else out_unit
    reasons["units"] = (f"load {', '.join(f'{c} {v}' for c, v in load_units.items())}: header hints, "
                        f"else N and N·m; output {shown_out}: {out_why}")
    peaks = np.abs(f).max(axis=0)
    full_scale = {c: full_scale_of(p) if p else 1.0 for c, p in zip(components, peaks, strict=True)}
    notes += [f"full_scale {c}: no load on {c} in the data; 1 is a placeholder"
              for c, p in zip(components, peaks, strict=True) if not p]
    reasons["full_scale"] = full_scale_reason(dict(zip(components, peaks, strict=True)), load_units)
    reps = {row[i].strip() for row in rows for i in special if special[i] == "repetition"
            and i < len(row) and row[i].strip()}
    reasons["min_repetitions"] = (f"{len(reps)} distinct values in {shown(columns['repetition'])}"
                                  if "repetition" in columns else
                                  "no repetition column: one repetition in this file")
    in_volts = out_unit in ("V", "mV/V") and 0.1 <= peak_out <= 10
    peak = f"{peak_out:g} {out_unit}"
    if out_units:  # outputs in several units: each output's own peak, in its own unit
        peak = ", ".join(f"{o} {float(np.abs(u[:, j]).max()):g} {out_units[o]}"
                         for o, j in zip(outputs, prime, strict=True))
    reasons["scaling"] = (f"outputs peak at {peak}, of order 1 as Table 2's gamma "
                          "assumes" if in_volts else f"outputs peak at {peak}, not "
                          "volts of order 1 as Table 2's gamma assumes: divide by each full-scale output")
    reasons["csv"] = (f"{'the default' if sep == ',' else 'detected'}: \"{sep}\"-separated"
                      f"{', decimal comma' if decimal == ',' else ''}")
    zero = None
    if not (f == 0).all(axis=1).any():  # gravity never switches off: no zero to subtract
        zero = "intercept"
        reasons["zero"] = (f"no row of the {len(f):,} read has every load 0: each output's "
                           "offset is fitted with the loads (an intercept), and the model "
                           "keeps it, so logs need no tare")
    gamma = method = None
    many = (f != 0).sum(axis=1) >= POSE_LOADS
    if zero and many.mean() >= POSE_SHARE:  # poses of a known mass
        gamma = POSE_GAMMA
        reasons["svr"] = (f"{POSE_LOADS} or more components loaded at once in {100 * many.mean():.0f} "
                          "% of the rows and none unloaded (poses of a mass): their chi inputs move "
                          f"together, and a kernel wider than Table 2's (gamma {POSE_GAMMA:g}, "
                          f"delta^2 = {0.5 / POSE_GAMMA:g}) held out better on simulated pose sets "
                          "(docs/rigs.md)")
        method = POSE_METHOD
        reasons["method"] = ("poses of a mass: the model or the least-squares matrix with its "
                             "offset, whichever has the lower error on poses held out in 5 folds "
                             "(fit's verdict); the matrix beat the model on a public eight-gauge "
                             "set (docs/rigs.md)")
    for i in set(usable) - set(mapped) - set(special):
        ignored[i] = ("a timestamp: not used" if i in stamps
                      else "not a load component or an output channel")
    return Guess(
        path=path, columns=columns,
        units={"load": next(iter(load_units.values())) if not mixed else "mixed", "output": out_unit},
        full_scale=full_scale, min_repetitions=max(1, len(reps)),
        scaling="none" if in_volts else "full_scale", sep=sep, decimal=decimal, reasons=reasons,
        ignored=[Ignored(i + 1, names[i], r) for i, r in sorted(ignored.items())], notes=notes,
        rows=len(table), keys=("repetition", "axis", *components, *outputs),
        components=components, outputs=outputs, load_units=load_units if mixed else None,
        output_units=out_units, zero=zero, gamma=gamma, method=method,
    )


def _numbers(rows: list[list[str]], cols: list[int], decimal: str) -> np.ndarray:
    """The rows whose every column in ``cols`` holds a number, as floats (rows, len(cols)).

    Each distinct cell is read once (a pose log repeats its loads and ADC counts on
    thousands of lines)."""
    read: dict[str, float | None] = {}

    def number(cell: str) -> float | None:
        c = cell.strip().replace(decimal, ".")
        v = float(c) if NUMBER.fullmatch(c) else None
        return v if v is not None and math.isfinite(v) else None  # 1e400 matches, but is no reading

    out = []
    for row in rows:
        values = []
        for i in cols:
            cell = row[i] if i < len(row) else ""
            v = read[cell] if cell in read else read.setdefault(cell, number(cell))
            if v is None:
                break
            values.append(v)
        else:
            out.append(values)
    return np.array(out, dtype=float).reshape(-1, len(cols))


def _pair(f: np.ndarray, u: np.ndarray, components: tuple[str, ...], channels: list[str],
          notes: list[str], named: bool = False) -> tuple[list[int], dict[str, str]]:
    """Each component's prime output: the channel its single-load rows move most.

    Score: a channel's range over the component's rows (and the unloaded ones),
    divided by its range over the whole file.  Returns the channel index per
    component and the reason; channels in order, with a note, when the scores do
    not name one channel per component.
    """
    span = np.ptp(u, axis=0)
    span[span == 0] = np.inf
    loaded = f != 0
    combined = int((loaded.sum(axis=1) > 1).sum())
    if combined:
        notes.append(f"{combined} rows load more than one component (a moment on a lever arm "
                     "loads a force too): fit fits them jointly (docs/rigs.md)")
    if named:
        return list(range(len(components))), {
            c: f"the sensor's own reading of {c}, named like the component" for c in components}
    peak = np.abs(f).max(axis=0)
    # a row belongs to the component it loads most, relative to that component's peak
    main = np.argmax(np.abs(f) / np.where(peak > 0, peak, np.inf), axis=1)
    score = np.zeros((len(components), u.shape[1]))
    for a in range(len(components)):
        rows = loaded[:, a] & (main == a) | ~loaded.any(axis=1)
        if loaded[rows, a].any():
            score[a] = np.ptp(u[rows], axis=0) / span
    best = [int(np.argmax(s)) for s in score]
    if len(set(best)) == len(best) and all(score[a, j] > 0 for a, j in enumerate(best)):
        return best, {c: f"prime output of {c}: {c} alone moves it over {100 * score[a, best[a]]:.3g} % "
                      f"of its span (the next channel {100 * np.sort(score[a])[-2]:.2g} %)"
                      for a, c in enumerate(components)}
    notes.append("the single-load rows do not pair each component with its own channel; "
                 f"took the channels in order ({', '.join(channels)}): check outputs:")
    return list(range(len(components))), {c: f"channel {k + 1} in order, for {c}"
                                          for k, c in enumerate(components)}


def header_unit(header: str, moment: bool) -> tuple[str | None, str | None]:
    """(unit, None) from a header's unit word in any common spelling (``[N·m]``, ``(N mm)``,
    ``_Nm``, ``[kgf]``), or (None, the word) when it names no unit fsdecouple knows, or
    (None, None) without one.  ``moment``: a moment's header (a bare ``N`` is then no moment)."""
    words = [h.strip() for h in _BRACKETS.findall(header)]
    tail = re.split(r"[\s_]+", re.sub(r"[\[(][^\])]*[\])]", " ", header).strip())
    table = _MOMENT_HINTS if moment else LOAD_HINTS
    # Mx_Nm, Fx_gf: a unit after the name (a word there that is no unit is part of the name)
    for w in words + tail[-1:] * (len(tail) > 1):
        unit = table.get(w.lower()) or _SPELLED.get(unit_key(w))
        if unit is not None and (unit in MOMENT_UNITS) == moment:
            return unit, None
    return None, next((w for w in words if w), None)


def _load_units(names: list[str], loads: dict[str, int], components: tuple[str, ...],
                f: np.ndarray, notes: list[str]) -> dict[str, str]:
    """Each component's unit: the header's hint, else N for forces and N·m for moments."""
    units, unknown = {}, {}
    for c in components:
        units[c], word = header_unit(names[loads[c]], c[0] == "m")
        if units[c] is None and word is not None:
            unknown[c] = word
    missing = [c for c in components if units[c] is None]
    for c in missing:
        units[c] = "N·m" if c[0] == "m" else "N"
    if unknown:
        notes.append("no known unit in " + ", ".join(f"{shown(names[loads[c]])} ('{w}')"
                                                     for c, w in unknown.items())
                     + ": took N for forces and N·m for moments; set units: in the config")
    if set(missing) - set(unknown):
        notes.append(f"no unit in the headers of {', '.join(c for c in missing if c not in unknown)}"
                     ": took N for forces and N·m for moments")
    return units

