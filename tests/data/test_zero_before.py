"""Zero rows anywhere (issue 22): a row loading several components is zeroed by the
nearest zero row before it."""

from __future__ import annotations

import numpy as np
import pandas as pd

from fsdecouple.axes import Layout
from fsdecouple.data.zero import zero_before, zero_correct


def test_each_row_takes_the_nearest_zero_row_before_it_or_the_first_after():
    rep = np.array([1, 1, 1, 1, 1, 2, 2, 2, 2])
    zero = np.array([0, 1, 0, 0, 1, 0, 0, 1, 0], dtype=bool)
    # brute force: scan back within the repetition, else forward
    want = []
    for i in range(rep.size):
        back = [j for j in range(i, -1, -1) if zero[j] and rep[j] == rep[i]]
        fwd = [j for j in range(i, rep.size) if zero[j] and rep[j] == rep[i]]
        want.append(back[0] if back else fwd[0])
    assert zero_before(rep, zero).tolist() == want


def test_a_zero_row_in_the_middle_of_a_sweep_zeroes_the_rows_after_it():
    layout = Layout.named(("fy", "mx"), ("a", "b"))
    f = np.array([[0, 0], [1, 0.1], [0, 0], [2, 0.2], [0, 0], [1, 0], [2, 0]], dtype=float)
    drift = np.array([0.0, 0.0, 0.5, 0.5, 0.0, 0.0, 0.0])  # the zero moved mid-sweep
    u = np.column_stack([f[:, 0] + drift, f[:, 1] + drift])
    t = pd.DataFrame({"repetition": 1, "axis": ["mx"] * 4 + ["fy"] * 3, "file": "c.csv",
                      "row": np.arange(7) + 2, "fy": f[:, 0], "mx": f[:, 1],
                      "a": u[:, 0], "b": u[:, 1]})
    points, _ = zero_correct(t, layout, "before")
    # exact up to the rounding of (f + 0.5) - 0.5 (a few ulps of 1)
    np.testing.assert_allclose(points[["a", "b"]].to_numpy(), f, rtol=0, atol=4 * np.finfo(float).eps)
