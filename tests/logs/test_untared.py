"""A count log applied without a tare: the hint says why every row is extrapolated (issue 34).

A load cell's raw zero is hundreds of thousands of counts, while its calibration spans
the zero-corrected outputs: a log applied without ``--tare`` or ``--zero`` decoupled
zero load to hundreds of gram-force, every row 'extrapolated', and the warning only said
"outside the calibrated range".
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from conftest import ROOT, invoke

LOADCELL = ROOT / "sample_data" / "loadcell"


@pytest.fixture(scope="module")
def loadcell_model(tmp_path_factory):
    path = tmp_path_factory.mktemp("lc") / "lc.json"
    invoke(["fit", LOADCELL / "calibration.csv", "-c", ROOT / "configs" / "loadcell.yaml",
            "-o", path, "--no-verdict"])
    return path


def _unloaded_log(path, rows=50, seed=0):
    """The calibration's raw zero row (its first), repeated with noise: an unloaded log."""
    raw = pd.read_csv(LOADCELL / "calibration.csv").iloc[0][["ch0", "ch1", "ch2"]].to_numpy(float)
    noise = np.random.default_rng(seed).normal(0.0, 20.0, (rows, 3))
    pd.DataFrame(np.round(raw + noise), columns=["ch0", "ch1", "ch2"]).to_csv(path, index=False)
    return raw


def test_an_untared_count_log_gets_the_tare_hint(loadcell_model, tmp_path):
    log = tmp_path / "log.csv"
    raw = _unloaded_log(log)
    r = invoke(["apply", loadcell_model, log, "-o", tmp_path / "f.csv"])
    hint = [ln for ln in r.stderr.splitlines() if "constant offset" in ln]
    assert len(hint) == 1 and "--tare N" in hint[0] and "--zero" in hint[0], r.stderr
    assert "most rows (50 of 50)" in hint[0]
    # the typical value it quotes is the log's own raw level of the channel it names
    name = hint[0].split("constant offset (")[1].split(":")[0]
    median = float(hint[0].split("typically ")[1].split()[0])
    assert median == pytest.approx(raw[["ux", "uy", "uz"].index(name)], abs=60)


def test_a_tared_log_or_a_log_in_range_gets_no_hint(loadcell_model, tmp_path):
    log = tmp_path / "log.csv"
    _unloaded_log(log)
    r = invoke(["apply", loadcell_model, log, "-o", tmp_path / "f.csv", "--tare", "10"])
    assert "constant offset" not in r.stderr and "extrapolated" not in r.stderr, r.stderr


def test_a_long_block_s_median_is_taken_over_a_sample_that_places_it():
    """block_median samples MEDIAN_ROWS rows of a long block: the median it gives lies
    within a small fraction of the outputs' spread of the whole block's; a short block
    is taken whole (exactly np.median)."""
    from fsdecouple.logs.untared import MEDIAN_ROWS, block_median

    rng = np.random.default_rng(3)
    # a drifting, noisy raw level (counts) about an offset of 750,000 on one output
    n = 131_072
    u = np.column_stack([750_000 + np.linspace(-5_000, 5_000, n) + rng.normal(0, 2_000, n),
                         rng.normal(0, 1, n), rng.standard_cauchy(n)])
    got, whole = block_median(u, 2.0), np.median(u * 2.0, axis=0)
    spread = np.subtract(*np.percentile(u * 2.0, [75, 25], axis=0))
    assert np.all(np.abs(got - whole) <= 0.02 * spread), (got, whole, spread)
    short = u[:MEDIAN_ROWS]
    np.testing.assert_array_equal(block_median(short), np.median(short, axis=0))
