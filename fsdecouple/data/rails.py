"""Channels at a rail (issue 32 item 3): a reading within 5 % of its range's ends.

An amplifier or ADC near the end of its range no longer follows the load (it clips, or
bends before it does), so a calibration point where an output sits there is no point of
the sensor's model.  The range is the config's ``limits:`` where given, else, for raw
ADC counts (``units: {output: count}``), 0 .. 2^k - 1 of the converter the readings
show (:func:`fsdecouple.data.magnitudes.adc_bits`).  Such points are left out with one
warning per channel naming its lines, or refused with ``--strict``.

Near is not yet at: a channel within 5 % of an end may still follow the load (on the
public eight-gauge set, 14 of 60 poses read 13 .. 52 counts of 1023 on some channel, each
within 2.4 robust sigmas of that channel's linear response to the loads fitted on the
other poses; leaving them out raised the held-out error of a least-squares matrix by
13 %).  So a near point is left out only when its reading is more than :data:`FOLLOWS`
robust sigmas (1.4826 MAD of the other points' residuals) from the channel's linear
response to the loads with an offset, least squares on the points not near; the points
near but following are kept, named in one note.  With too few other points to judge
(fewer than twice the response's unknowns: ten poses of six loads) the near points are
kept too, with a note that says so: left out, a prior's ten poses fell to five, too few
to fit.  Only poses are
checked (the averaged samples of files with a timestamp column, data/poses.py): a sweep's
single readings keep ``limits:`` for ``apply``'s saturated status, as before.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError, where

RAIL = 0.05  # of a channel's range: a reading this close to either end sits at a rail
FOLLOWS = 3.0  # robust sigmas from its linear response within which a near reading follows


def ranges(settings, outputs, raw: np.ndarray, bits: int | None) -> dict[str, tuple[float, float, str]]:
    """(lo, hi, whence) of each output whose range is known: ``limits:``, else a k-bit ADC's."""
    out = {}
    for c in outputs:
        if c in settings.limits:
            lo, hi = settings.limits[c]
            out[c] = (lo, hi, "the config's limits:")
        elif bits is not None and settings.output_unit == "count" and raw.size:
            out[c] = (0.0, float(2 ** bits - 1), f"a {bits}-bit ADC's, from the data")
    return out


def following(f: np.ndarray, u: np.ndarray, near: np.ndarray) -> np.ndarray | None:
    """Which ``near`` points still follow the load: within :data:`FOLLOWS` robust sigmas of
    the linear response u ~ f b + c fitted by least squares on the other points.  None when
    there are too few other points to fit and judge it (fewer than twice its unknowns)."""
    out = np.zeros(len(u), dtype=bool)
    rest = ~near
    if rest.sum() < 2 * (f.shape[1] + 1):
        return None
    design = np.column_stack([f, np.ones(len(u))])
    b, *_ = np.linalg.lstsq(design[rest], u[rest], rcond=None)
    r = u - design @ b
    scale = 1.4826 * np.median(np.abs(r[rest] - np.median(r[rest])))
    if not scale > 0:
        return out
    out[near] = np.abs(r[near]) <= FOLLOWS * scale
    return out


def _points(mask, files, rows, single: bool) -> str:
    """``3 points (lines 4, 9, 12)`` of one file, ``1 point (pose26.csv line 2)`` of several."""
    n = int(mask.sum())
    at = [str(r) if single else f"{Path(f).name} line {r}"
          for f, r in zip(files[mask][:6], rows[mask][:6], strict=True)]
    listed = ", ".join(at) + (", ..." if n > 6 else "")
    plural = "s" if n > 1 else ""
    return f"{n} point{plural} ({f'line{plural} ' if single else ''}{listed})"


def at_rail(frame, outputs, known: dict, strict: bool, loads=()) -> tuple[np.ndarray, list[str]]:
    """Which rows of ``frame`` (points with ``file``, ``row``, ``loads`` and ``outputs``) to
    keep, and the warnings.

    A row is left out when any output with a known range is within :data:`RAIL` of its
    range's ends and no longer follows the load (:func:`following`, judged when ``loads``
    are given); ``strict`` refuses any such near row, naming the file, line and column.
    """
    keep = np.ones(len(frame), dtype=bool)
    notes = []
    rows = frame["row"].to_numpy()
    files = frame["file"].to_numpy()
    single = len(set(files)) == 1
    for c in outputs:
        if c not in known:
            continue
        lo, hi, whence = known[c]
        u = frame[c].to_numpy(dtype=float)
        margin = RAIL * (hi - lo)
        near = (u <= lo + margin) | (u >= hi - margin)
        if not near.any():
            continue
        i = int(np.argmax(near))
        end = "upper" if u[i] >= hi - margin else "lower"
        if strict:
            raise InputError(f"{where(files[i], int(rows[i]), c)}: {u[i]:g} is within {RAIL:.0%} of "
                             f"the {end} end of its range {lo:g} .. {hi:g} ({whence}): strict mode "
                             "refuses readings near a rail, where a channel may no longer follow "
                             "the load", argument="strict")
        path = files[i] if single else Path(files[i]).parent
        f = frame[list(loads)].to_numpy(dtype=float) if len(loads) else np.zeros((len(u), 0))
        kept = following(f, u, near) if len(loads) else np.zeros(len(u), dtype=bool)
        head = f"{path}: output {c} is within {RAIL:.0%} of an end of its range {lo:g} .. {hi:g} ({whence})"
        if kept is None:  # too few points to tell: near is not at, and leaving them out
            # can leave a small set (a prior's ten poses) with too few to fit
            others = int((~near).sum())
            notes.append(f"{head} on {_points(near, files, rows, single)}; {others} other "
                         f"point{'s are' if others != 1 else ' is'} too few to judge whether it "
                         "still follows the load there, so they are kept (strict mode refuses "
                         "them)")
            continue
        out = near & ~kept
        if out.any():
            notes.append(f"{head} on {_points(out, files, rows, single)}: a channel at its rail "
                         f"no longer follows the load (more than {FOLLOWS:g} robust sigmas from "
                         "its linear response to the loads on the other points), so they are "
                         "left out (strict mode refuses them)")
        if kept.any():
            notes.append(f"{head} on {_points(kept, files, rows, single)}, but follows the load "
                         f"there (within {FOLLOWS:g} robust sigmas of its linear response to the "
                         "loads on the other points), so they are kept (strict mode refuses them)")
        keep &= ~out
    return keep, notes
