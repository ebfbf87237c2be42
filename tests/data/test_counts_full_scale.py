"""Units and full scale from the data (issue 32 item 4): whole numbers within 0 .. 2^k - 1
are ADC counts; a full scale is the largest load rounded up by at most 25 %, with its reason."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fsdecouple.data.magnitudes import FINE_STEPS, adc_bits, full_scale_of, nice_ceil


@pytest.mark.parametrize("seed", range(5))
def test_a_full_scale_is_the_peak_rounded_up_by_at_most_a_quarter(seed):
    for peak in np.random.default_rng(seed).lognormal(0.0, 4.0, 400):
        fs = full_scale_of(float(peak))
        assert peak * (1 - 1e-12) <= fs <= 1.25 * peak
        mantissa = fs / 10.0 ** math.floor(math.log10(fs) + 1e-12)
        assert any(math.isclose(mantissa, m) for m in (*FINE_STEPS, 10.0)), (peak, fs)
        # the coarser 1, 2, 2.5, 5 x 10^k is kept whenever it is close enough
        if nice_ceil(float(peak)) <= 1.25 * peak:
            assert fs == nice_ceil(float(peak))


def test_the_public_eight_gauge_peaks():
    # issue 32: init guessed 20 N for 10.08 N and 0.5 N·m for 0.385 N·m
    assert full_scale_of(10.08) == 12 and full_scale_of(0.385) == 0.4


def test_counts_are_whole_numbers_within_a_converters_range():
    rng = np.random.default_rng(0)
    ten = rng.integers(100, 1000, 5000)
    assert adc_bits(ten) == 10
    ten[7] = 4598  # a serial misread: beyond 10 bits, but one in 5000
    assert adc_bits(ten) == 10
    assert adc_bits(rng.integers(0, 60000, 100)) == 16
    assert adc_bits(ten - 500) is None  # negative: not raw counts
    assert adc_bits(ten + 0.5) is None  # not whole numbers
