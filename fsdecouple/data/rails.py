"""Channels at a rail (issue 32 item 3): a reading within 5 % of its range's ends.

An amplifier or ADC near the end of its range no longer follows the load (it clips, or
bends before it does), so a calibration point where an output sits there is no point of
the sensor's model.  The range is the config's ``limits:`` where given, else, for raw
ADC counts (``units: {output: count}``), 0 .. 2^k - 1 of the converter the readings
show (:func:`fsdecouple.data.magnitudes.adc_bits`).  Such points are left out with one
warning per channel naming its lines, or refused with ``--strict``.  Only poses are
checked (the averaged samples of files with a timestamp column, data/poses.py): a sweep's
single readings keep ``limits:`` for ``apply``'s saturated status, as before.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError, where

RAIL = 0.05  # of a channel's range: a reading this close to either end sits at a rail


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


def at_rail(frame, outputs, known: dict, strict: bool) -> tuple[np.ndarray, list[str]]:
    """Which rows of ``frame`` (points with ``file``, ``row`` and ``outputs``) to keep, and
    the warnings.

    A row is left out when any output with a known range is within :data:`RAIL` of its
    range's ends; ``strict`` refuses it instead, naming the file, line and column.
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
                             f"the {end} end of its range {lo:g} .. {hi:g} ({whence}): a channel "
                             "at its rail no longer follows the load; strict mode refuses it",
                             argument="strict")
        at = [str(r) if single else f"{Path(f).name} {r}"
              for f, r in zip(files[near][:6], rows[near][:6], strict=True)]
        lines = ", ".join(at) + (", ..." if near.sum() > 6 else "")
        path = files[i] if single else Path(files[i]).parent
        notes.append(f"{path}: output {c} is within {RAIL:.0%} of an end of its range {lo:g} .. "
                     f"{hi:g} ({whence}) on {int(near.sum())} point{'s' if near.sum() > 1 else ''} "
                     f"(lines {lines}): a channel at its rail no longer follows the load, so "
                     "they are left out (strict mode refuses them)")
        keep &= ~near
    return keep, notes
