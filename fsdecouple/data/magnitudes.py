"""Units and full scale from the data's magnitudes (issue 32 item 4), for ``init``.

Whole-number readings within 0 .. 2^k - 1 are a k-bit ADC's raw counts; a full scale is
the largest applied load rounded up by at most 25 % to a round number.
"""

from __future__ import annotations

import math


def nice_ceil(value: float) -> float:
    """The smallest 1, 2, 2.5 or 5 x 10^k that is >= ``value`` (> 0)."""
    k = math.floor(math.log10(value))
    # .12g: 2.5 x 10^-1 is 0.25, not 0.25000000000000006
    return next(float(f"{m * 10.0**e:.12g}") for e in (k - 1, k, k + 1)
                for m in (1.0, 2.0, 2.5, 5.0) if m * 10.0**e >= value * (1 - 1e-12))


ADC_BITS = (8, 10, 12, 14, 16, 18, 20, 24)  # common converter resolutions
# Readings of a k-bit ADC lie within 0 .. 2^k - 1 but for rare serial misreads (459 read
# as 4598): the range is the smallest that holds this fraction of the readings.
ADC_QUANTILE = 0.999


def adc_bits(values) -> int | None:
    """k when ``values`` are whole numbers >= 0 that a k-bit ADC gives (0 .. 2^k - 1 but for
    misreads, :data:`ADC_QUANTILE`), the smallest such k of :data:`ADC_BITS`; else None."""
    import numpy as np  # init's header guess needs no numpy; this runs on its numbers

    v = np.asarray(values, dtype=float).ravel()
    v = v[np.isfinite(v)]
    if not v.size or v.min() < 0 or (v != np.round(v)).any():
        return None
    top = float(np.quantile(v, ADC_QUANTILE, method="higher"))
    return next((k for k in ADC_BITS if top <= 2 ** k - 1), None)


# Full scale from the data (issue 32): the largest load rounded up to a round number, by
# at most 25 %; 1, 2, 2.5, 5 x 10^k when one is that close, else the finer steps.
FULL_SCALE_MARGIN = 1.25
FINE_STEPS = (1.0, 1.2, 1.5, 1.8, 2.0, 2.5, 3.0, 3.5, 4.0, 5.0, 6.0, 7.0, 8.0)


def full_scale_of(peak: float) -> float:
    """The full scale guessed from the largest |load| ``peak`` (> 0): :func:`nice_ceil` when it
    is within :data:`FULL_SCALE_MARGIN` of the peak, else the next of :data:`FINE_STEPS`
    x 10^k (consecutive steps differ by at most 25 %, so one always is)."""
    nice = nice_ceil(peak)
    if nice <= FULL_SCALE_MARGIN * peak:
        return nice
    k = math.floor(math.log10(peak))
    return next(float(f"{m * 10.0**e:.12g}") for e in (k - 1, k, k + 1)
                for m in FINE_STEPS if m * 10.0**e >= peak * (1 - 1e-12))


def full_scale_reason(peaks: dict, units: dict) -> str:
    """The reason init prints for its full scales: each peak, its full scale and the margin."""
    parts = [f"{c} {p:g} {units[c]} -> {full_scale_of(p):g} (+{100 * (full_scale_of(p) / p - 1):.0f} %)"
             if p else f"{c}: no load" for c, p in peaks.items()]
    return ("largest |load| per component, rounded up by at most 25 % to a round number ("
            + ", ".join(parts) + ")")


