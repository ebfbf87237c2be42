"""A zero-corrected calibration set: the data every fit and cross-validation uses."""

from __future__ import annotations

import collections
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..axes import DEFAULT, Layout
from ..config import Settings
from ..errors import InputError
from .calibration_csv import read_calibration_table
from .zero import assign_sweeps, has_zero_row, intercept_offsets, out_and_back, stack, zero_correct


@dataclass(frozen=True)
class CalibrationSet:
    """Zero-corrected single-axis calibration points of several repetitions.

    Attributes
    ----------
    points : DataFrame
        One row per calibration point in file order (repetition, then row), with
        ``repetition, axis, file, row, fx, fy, fz`` [N], ``ux, uy, uz`` [V]
        (zero-corrected) and ``ux_raw, uy_raw, uz_raw`` [V].
    offsets : DataFrame
        Zero offsets removed, one row per (repetition, axis) sweep [V].
    files : tuple of (str, str)
        Each input file and its SHA-256.
    skipped : tuple of str
        Rows left out, with the reason.
    excluded : tuple of str
        Points dropped by ``--exclude`` (also in ``skipped``; recorded in the model's
        provenance).
    warnings : tuple of str
        Things a technician should look at; the data are still usable.
    layout : Layout
        The sensor's components (axes.py): sweep labels, load and output columns.
    zero : str or None
        How the sweeps were zeroed: ``rows``, ``fit`` or ``before`` (data/zero.py).
    zero_auto : bool
        ``fit`` was chosen because the sweeps go out and back, not by the config: the
        certificate's ISO 376 figures still take deflections from the zero rows.
    noise : ndarray, optional
        Pose logs (data/poses.py): sigma of each averaged output, from the samples' scatter.
    """

    points: pd.DataFrame
    offsets: pd.DataFrame
    files: tuple[tuple[str, str], ...] = ()
    skipped: tuple[str, ...] = ()
    warnings: tuple[str, ...] = field(default=())
    excluded: tuple[str, ...] = ()
    layout: Layout = DEFAULT
    zero: str | None = None  # how the sweeps were zeroed (data/zero.py); None: not recorded
    zero_auto: bool = False  # zero: fit chosen for out-and-back sweeps (zero.out_and_back)
    noise: np.ndarray | None = None  # pose logs: sigma of each averaged output (poses.py)
    # a temperature column's drift terms, the outputs corrected to T0 by them (fitting/temperature.py)
    temperature_fit: Any = None
    # soak files (every load zero, temperature varying): rows for the offset drift b_i only
    soak: pd.DataFrame | None = None
    # the settings the set was read with (load_calibration): what fit and run_cv use when
    # given none, so a lab's gram-force set is not fitted as the paper's sensor in newtons
    settings: Any = None

    @property
    def source(self) -> str:
        """The calibration file, or the directory of the files, for messages."""
        return _source(self.files)

    @property
    def repetitions(self) -> list[int]:
        return sorted(int(r) for r in self.points["repetition"].unique())

    def subset(self, repetitions) -> CalibrationSet:
        """The same set restricted to some repetitions (for cross-validation)."""
        reps = set(int(r) for r in repetitions)
        unknown = reps - set(self.repetitions)
        if unknown:
            raise InputError(
                f"repetition {sorted(unknown)[0]} is not in the calibration set "
                f"(it has {', '.join(map(str, self.repetitions))})"
            )
        keep = self.points["repetition"].isin(reps)
        return replace(
            self, points=self.points[keep].reset_index(drop=True),
            offsets=self.offsets[self.offsets["repetition"].isin(reps)].reset_index(drop=True),
        )

    def select(self, mask) -> CalibrationSet:
        """The points where ``mask`` is true (a held-out round's training or test points).

        Zero correction stays as it was done on the whole set: a held-out zero row
        still zeroed its sweep.
        """
        return replace(self, points=self.points[np.asarray(mask, dtype=bool)].reset_index(drop=True))

    def sweep(self, axis: str) -> pd.DataFrame:
        """All points whose loaded axis is ``axis``, in file order."""
        return self.points[self.points["axis"].to_numpy() == axis]

    def sweep_columns(self, axis: str, columns) -> list[np.ndarray]:
        """Columns of :meth:`sweep` as arrays, without building its frame (fit, cv)."""
        mine = self.points["axis"].to_numpy() == axis
        return [self.points[c].to_numpy()[mine] for c in columns]

    @property
    def forces(self) -> np.ndarray:
        return self.points[list(self.layout.loads)].to_numpy()

    @property
    def voltages(self) -> np.ndarray:
        return self.points[list(self.layout.outputs)].to_numpy()

    def load_grid(self, axis: str) -> dict[int, np.ndarray]:
        """Sorted distinct loads [N] of each repetition's ``axis`` sweep."""
        reps, loads = self.sweep_columns(axis, ["repetition",
                                                self.layout.loads[self.layout.index(axis)]])
        if not reps.size:
            return {}
        # one sort for all repetitions: a groupby loop costs a pandas frame per repetition
        order = np.lexsort((loads, reps))
        reps, loads = reps[order], loads[order]
        new = np.ones(reps.size, dtype=bool)
        new[1:] = (reps[1:] != reps[:-1]) | (loads[1:] != loads[:-1])
        reps, loads = reps[new], loads[new]
        cuts = np.flatnonzero(reps[1:] != reps[:-1]) + 1
        return {int(r[0]): g for r, g in zip(np.split(reps, cuts), np.split(loads, cuts),
                                             strict=True)}


def _source(files) -> str:
    if not files:
        return "calibration set"
    if len(files) == 1:
        return str(files[0][0])
    return str(Path(files[0][0]).parent)


def split_soak(table: pd.DataFrame, layout: Layout):
    """The soak files of ``table`` set apart: files whose every row loads nothing, logged over
    a temperature span (issue 31: they identify the offset drift b_i alone).  Returns the
    table without them, their rows (None when there are none) and a note per file.  A soak
    without a temperature column, or spanning less than the temperature fit's minimum, is
    refused: it could only be a sweep with no loaded point."""
    from ..temperature_units import MIN_SPAN

    if "file" not in table.columns:  # a table built in code: no files to set apart
        return table, None, []
    zero = (stack(table, layout.loads) == 0.0).all(axis=1)
    files = table["file"].to_numpy()
    # per file at once (a mask per file over the whole table was quadratic in the files)
    names, first, of = np.unique(files, return_index=True, return_inverse=True)
    loaded = np.bincount(of.ravel(), weights=~zero, minlength=names.size) > 0
    soaks = [names[i] for i in np.argsort(first) if not loaded[i]]  # in file order
    if not soaks or len(soaks) == names.size:  # nothing loaded at all: zero.py says so
        return table, None, []
    notes = []
    for f in soaks:
        if "temperature" not in table.columns:
            raise InputError(f"{f}: every row's loads are zero (a soak), but the set has no "
                             "temperature column: a soak only serves the offset drift b_i over "
                             "a temperature span, and it is not a sweep")
        t = table.loc[files == f, "temperature"].to_numpy(dtype=float)
        if np.ptp(t) < MIN_SPAN:
            raise InputError(f"{f}: every row's loads are zero (a soak), but its temperatures "
                             f"span {np.ptp(t):.3g} K, less than the {MIN_SPAN:g} K the "
                             "temperature fit needs; it is not a sweep either")
        notes.append(f"{f}: {int((files == f).sum())} rows with every load zero from "
                     f"{t.min():.4g} to {t.max():.4g} degC (a soak): used for the offset drift "
                     "b_i only, not for fitting the decoupling model and not a repetition")
    is_soak = np.isin(files, soaks)
    return (table[~is_soak].reset_index(drop=True), table[is_soak].reset_index(drop=True), notes)


def from_table(table: pd.DataFrame, settings: Settings, files=(), skipped=(),
               combined: bool = False) -> CalibrationSet:
    """Validate a long table (as :func:`read_calibration_table` returns) and zero-correct it.

    ``combined`` (``validate``): rows loading several components keep their labelled sweep and
    its zero rows; without it (``fit``) they are fitted jointly and zeroed by the zero row before.
    """
    layout = settings.layout
    dead_channels(table, layout, _source(files))
    table, soak, soak_notes = split_soak(table, layout)
    table = assign_sweeps(table, layout, combined, settings.full_scale)
    # no unloaded row (poses of a known mass): each output's offset is fitted (zero.py)
    intercept = settings.zero == "intercept" or (settings.zero is None
                                                 and not has_zero_row(table, layout))
    several = not combined and ((stack(table, layout.loads) != 0.0).sum(axis=1) > 1).any()
    rep_of, axis_of = table["repetition"].to_numpy(), table["axis"].to_numpy()
    reps = np.unique(rep_of)
    if len(reps) < settings.min_repetitions:
        raise InputError(
            f"{_source(files)}: {len(reps)} "
            f"repetition{'s' if len(reps) != 1 else ''}, the config requires at least "
            f"{settings.min_repetitions} (min_repetitions)"
            + (f"; a single CSV without a '{settings.columns['repetition']}' column is one "
               "repetition" if len(files) == 1 and len(reps) == 1 else "")
        )
    # one grouping, not a scan of the table per repetition (quadratic in thousands)
    have: dict = {}
    for rep, axis in zip(rep_of.tolist(), axis_of.tolist(), strict=True):
        have.setdefault(rep, set()).add(axis)
    # rows loading several components are fitted jointly: no sweep need isolate a component
    for rep in [r for r in sorted(have) if len(have[r]) < layout.n][:0 if several else 1]:
        missing = [a for a in layout.labels if a not in have[rep]]
        if missing:
            first = table.iloc[int(np.argmax(rep_of == rep))]
            every = "all three axes" if layout.is_default else f"all {layout.n} components"
            raise InputError(
                f"{first['file']}: repetition {rep} has no {' or '.join(missing)} sweep; "
                f"every repetition must calibrate {every}"
            )
    # rows loading several components (a lever arm): each row is zeroed by the nearest
    # zero row before it (docs/rigs.md); the polynomial of zero: fit assumes one load a sweep
    # sweeps out and back: offsets from all points measured better than the zero rows
    # (zero.out_and_back; zero: rows in the config keeps the rows)
    back = not intercept and not several and settings.zero is None \
        and settings.zero_method == "rows" and out_and_back(table, layout)
    method = "intercept" if intercept else settings.zero or (
        "before" if several else "fit" if back else settings.zero_method)
    warnings = list(soak_notes)
    if intercept:
        points, offsets = intercept_offsets(table, layout, settings.full_scale, _source(files))
        if settings.zero is None:
            warnings.append("no row is unloaded (all loads 0): each output's offset is fitted "
                            "with the loads as an intercept (zero: intercept); the model keeps "
                            "it, so decoupling a log needs no tare (docs/data.md)")
    else:
        points, offsets = zero_correct(table, layout, method)
    if back:
        warnings.append("the sweeps visit their loads twice (out and back): zeroed by offsets "
                        "fitted from all points (zero: fit), more accurate than the zero rows "
                        "on such sweeps (docs/tuning.md); 'zero: rows' in the config keeps the "
                        "zero rows")
    if several and not intercept:  # a typo in a single-axis set reads the same: say where, once
        rows = table[(table[list(layout.loads)].to_numpy() != 0.0).sum(axis=1) > 1]
        first = {}  # each file named once, with its first rows
        for f, r in zip(rows["file"][:3], rows["row"][:3], strict=True):
            first.setdefault(f, []).append(str(r))
        shown = "; ".join(f"{f}, row{'s' if len(r) > 1 else ''} {', '.join(r)}"
                          for f, r in first.items())
        many = "rows load" if len(rows) > 1 else "row loads"
        warnings.append(f"{len(rows)} {many} several components ({shown}"
                        f"{', ...' if len(rows) > 3 else ''}): fitted jointly (docs/rigs.md)")
    cs = CalibrationSet(points, offsets, tuple(files), tuple(skipped), layout=layout)

    def same(g, h) -> bool:
        return g.shape == h.shape and np.allclose(g, h, rtol=0, atol=1e-9)

    for axis in layout.labels:
        grids = cs.load_grid(axis)
        if not grids:  # rows loading several components, none of them mostly this one
            continue
        # the grid most repetitions share exactly (the first of a tie; counted, not compared
        # pairwise: 3,000 repetitions): an odd first repetition is named, not the five
        # that agree
        shared = collections.Counter((g.shape, g.tobytes()) for g in grids.values())
        ref_rep, ref = max(grids.items(), key=lambda kv: shared[(kv[1].shape, kv[1].tobytes())])
        odd = [rep for rep, g in grids.items() if not same(g, ref)]
        if odd:
            warnings.append(
                f"the {axis} sweep of repetition {odd[0]} uses a different load grid than "
                f"repetition {ref_rep} ({len(grids) - len(odd)} of {len(grids)} repetitions "
                "share that one); gamma compares repetitions at different loads")
    for a, axis in enumerate(layout.labels):
        # loads far from the full scale usually mean other units (kN, kgf) or a
        # wrong full_scale, and gamma (eq. 12) is a fraction of the full scale
        peak = float(np.abs(cs.points[layout.loads[a]]).max())
        fs, unit = settings.full_scale[a], settings.units.load_of(a)
        if peak > 1.05 * fs or peak < 0.2 * fs:
            warnings.append(
                f"the {axis} loads reach {peak:g} {unit}, the full scale is {fs:g} "
                f"{unit}: check the units (units: and scale: in the config) and "
                "full_scale"
            )
    seen: dict[str, str] = {}
    for name, digest in files:
        if digest in seen:
            warnings.append(f"{name} is byte for byte the same file as {seen[digest]}; "
                            "a repetition copied twice counts twice")
        seen.setdefault(digest, name)
    return CalibrationSet(points, offsets, tuple(files), tuple(skipped), tuple(warnings),
                          layout=layout, zero=method, zero_auto=back, soak=soak)


def dead_channels(table: pd.DataFrame, layout: Layout, source: str) -> None:
    """Refuse an output that never changes (a dead or disconnected channel), by name.

    A constant channel carries no load: the forward model and every chi divide by its
    span, and the overflow that follows would blame an innocent cell of another channel.
    """
    if len(table) < 2 or not layout.overdetermined:  # one output per component: fit names it
        return
    u = stack(table, layout.outputs).astype(float, copy=False)
    flat = np.flatnonzero(np.ptp(u, axis=0) == 0.0)
    if flat.size:
        names = ", ".join(f"'{layout.outputs[j]}'" for j in flat)
        value = u[0, flat[0]]
        raise InputError(f"{source}: output {names} is constant ({value:g} on every row): a dead "
                         "or disconnected channel carries no load; remove it from outputs: and "
                         "columns: in the config")


def load_calibration(path: str | Path, settings: Settings, exclude=(),
                     combined: bool = False, strict: bool = False) -> CalibrationSet:
    """Read, validate and zero-correct a calibration set (a directory or one CSV).

    ``exclude``: ``FILE:LINE`` lines to drop before zero correction (``fit --exclude``);
    FILE is a file of the set by path or by name, LINE as an editor numbers it (header 1).
    """
    specs = [parse_exclude(spec) for spec in exclude]
    # lines that are not a calibration point once read (a pose's later samples) or cannot
    # be read (a blank or garbled cell) are dropped before their cells are read
    read = read_calibration_table(path, settings, strict, specs)
    table, dropped = _exclude(read.table, exclude, read.excluded)
    cs = from_table(table, settings, read.files, [*read.skipped, *dropped], combined)
    hidden = tuple(f"{f}: hidden file, not read as a repetition" for f in read.hidden)
    hidden += read.warnings
    cs = replace(cs, excluded=tuple(dropped), noise=read.noise, settings=settings)
    return replace(cs, warnings=hidden + cs.warnings) if hidden else cs


EXCLUDED = ", row {row}: excluded as asked"  # how a dropped line is recorded (provenance)


def excluded_lines(records) -> list[str]:
    """The ``FILE:LINE`` of each line a model's fit left out (its provenance's
    ``excluded``, as :func:`_exclude` records them), FILE by name: the same lines of
    the same set, wherever it lies now.  Records of another form are ignored."""
    tail = re.compile(re.escape(EXCLUDED).replace(r"\{row\}", r"(\d+)") + "$")
    out = []
    for record in records or ():
        m = tail.search(str(record))
        if m:
            out.append(f"{Path(str(record)[:m.start()]).name}:{m.group(1)}")
    return out


def parse_exclude(spec) -> tuple[str, int]:
    """``FILE:LINE`` of ``--exclude`` as (FILE, LINE); LINE as an editor numbers it, header 1."""
    name, sep, row = str(spec).rpartition(":")
    if not sep or not name or not row.strip().isascii() or not row.strip().isdigit():
        raise InputError(f"excluded point {spec!r}: expected FILE:LINE, e.g. rep3.csv:17 (lines "
                         "as an editor numbers them, the header is line 1)", argument="exclude")
    line = int(row)
    if line < 2:
        raise InputError(f"excluded point {spec!r}: line {line} is the header or before it; "
                         "data rows start at line 2", argument="exclude")
    return name, line


def _exclude(table: pd.DataFrame, specs, unread=()) -> tuple[pd.DataFrame, list[str]]:
    """Drop the ``FILE:LINE`` points named; each must be a line of the set.

    ``unread``: (file, line) already dropped while reading (a pose's samples, a line that
    could not be parsed): excluded, and not looked for among the points.
    """
    if not specs:  # nothing to drop: the table as read
        return table, []
    drop = np.zeros(len(table), dtype=bool)
    dropped = []
    files = table["file"].to_numpy()
    names = np.array([Path(f).name for f in files])
    gone = {(Path(f).name, line): f for f, line in unread}
    gone.update({(f, line): f for f, line in unread})
    for spec in specs:
        name, row = parse_exclude(spec)
        in_file = (files == name) | (names == Path(name).name) if "/" not in name else files == name
        hit = np.flatnonzero(in_file & (table["row"].to_numpy() == row))
        key = (name if "/" in name else Path(name).name, row)
        if hit.size == 0 and key in gone:
            dropped.append(f"{gone[key]}{EXCLUDED.format(row=row)}")
            continue
        if hit.size == 0:
            known = "a file of the set" if not in_file.any() else f"a data line of {name}"
            raise InputError(f"excluded point {spec!r}: line {row} of {name} is not {known}",
                             argument="exclude")
        drop[hit] = True
        dropped.append(f"{files[hit[0]]}{EXCLUDED.format(row=row)}")
    return table[~drop].reset_index(drop=True), dropped


@dataclass(frozen=True)
class GrossError:
    """One calibration point moved away from its place (Section 4.4).

    ``offset`` [V] is added to the prime voltage of point ``point`` (1-based, file
    order) of the ``axis`` sweep of repetition ``repetition``.
    """

    axis: str
    repetition: int
    point: int
    offset: float

    @classmethod
    def parse(cls, spec: str, layout: Layout = DEFAULT) -> GrossError:
        """``AXIS:REP:POINT:OFFSET``; AXIS a label of ``layout`` (x; or a component, fx)."""
        parts = spec.split(":")
        try:
            axis, rep, point, offset = parts
            axis = layout.label_map().get(axis.strip().lower(), "")
            if not axis or "_" in rep + point + offset:  # int() and float() read 1_0 as 10
                raise ValueError
            ge = cls(axis, int(rep), int(point), float(offset))
        except ValueError:
            raise InputError(
                f"{spec!r}: expected AXIS:REP:POINT:OFFSET, AXIS one of "
                f"{', '.join(layout.labels)}, e.g. {layout.labels[0]}:1:5:0.2", argument="gross_error"
            ) from None
        if ge.repetition < 1 or ge.point < 1:
            raise InputError(f"{spec!r}: REP and POINT count from 1", argument="gross_error")
        if not np.isfinite(ge.offset):
            raise InputError(f"{spec!r}: OFFSET {offset.strip()!r} is not a finite number",
                             argument="gross_error")
        return ge

    def apply(self, table: pd.DataFrame, layout: Layout = DEFAULT) -> pd.DataFrame:
        """A copy of ``table`` with this point's prime voltage moved by ``offset``."""
        if self.axis not in layout.labels:
            raise InputError(f"no component '{self.axis}' (the sensor has "
                             f"{', '.join(layout.labels)})", argument="gross_error")
        idx = np.flatnonzero(
            (table["repetition"] == self.repetition).to_numpy()
            & (table["axis"] == self.axis).to_numpy()
        )
        if not idx.size:
            reps = sorted(set(table["repetition"]))
            raise InputError(f"the {self.axis} sweep has no repetition {self.repetition} "
                             f"(repetitions: {', '.join(map(str, reps))})", argument="gross_error")
        if self.point > idx.size:
            raise InputError(
                f"the {self.axis} sweep of repetition {self.repetition} has "
                f"{idx.size} points, no point {self.point}", argument="gross_error"
            )
        out = table.copy()
        col = out.columns.get_loc(layout.outputs[layout.index(self.axis)])
        out.iloc[idx[self.point - 1], col] += self.offset
        return out


def ingest_summary(calib, settings) -> dict[str, Any]:
    """Everything ``ingest`` reports, as plain data (also the ``--json`` document)."""
    axes = {}
    for a, axis in enumerate(calib.layout.labels):
        s = calib.sweep(axis)
        grid = np.unique(s[calib.layout.loads[a]].to_numpy())
        axes[axis] = {
            "points": int(len(s)),
            "points_per_repetition": {
                int(r): int(n) for r, n in s.groupby("repetition").size().items()
            },
            "load_min": float(grid.min()) if grid.size else None,
            "load_max": float(grid.max()) if grid.size else None,
            "load_levels": int(grid.size),
            "full_scale": settings.full_scale[a],
        }
    return {
        "sensor": settings.sensor,
        "units": {"load": settings.load_unit, "output": settings.output_unit},
        "files": [{"path": p, "sha256": h} for p, h in calib.files],
        "repetitions": calib.repetitions,
        "axes": axes,
        "offsets": calib.offsets.to_dict(orient="records"),
        **({"zero": "intercept"} if calib.zero == "intercept" else
           {"zero": "fit"} if settings.zero_method == "fit" else {}),
        "skipped": list(calib.skipped),
        "warnings": list(calib.warnings),
    }
