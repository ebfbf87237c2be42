"""The report's cross-validation tables, from cv.json documents made here."""

from __future__ import annotations

import re

from fsdecouple.reporting.cv_tables import gamma_tables, gross_tables


def _records(rounds, values):
    return [{"round": r, "test_set": r, "method": m, "axis": a, "metric": "gamma", "value": v}
            for r in rounds for (m, a), v in values.items()]


def _text(html: str) -> str:
    return " ".join(re.sub(r"<[^>]+>", " ", html).split())


def test_the_levels_protocols_end_points_have_their_own_table():
    """cv printed 'svr worst gamma 0.53 % F.S. on end points'; the report showed the
    interior rounds only, and the end points (the heaviest loads) nowhere."""
    interior = {("initial", "x"): 0.01, ("svr", "x"): 0.001, ("initial", "y"): 0.02,
                ("svr", "y"): 0.002}
    end = {("initial", "x"): 0.05, ("svr", "x"): 0.0016, ("initial", "y"): 0.03,
           ("svr", "y"): 0.0053}
    cv = {"protocol": "levels", "methods": ["initial", "svr"], "folds": [[1], [2], []],
          "records": _records([1, 2], interior), "end_records": _records([3], end)}
    html = gamma_tables(cv)
    assert 'id="table-gamma-end"' in html
    part = _text(html[html.index('id="table-gamma-end"'):])
    assert "3 end points 5.00 % 0.16 % 3.00 % 0.53 %" in part
    # the repetitions protocol has no end points: no such table
    assert "table-gamma-end" not in gamma_tables({**cv, "protocol": "repetitions"})


def test_the_gross_errors_offset_is_in_the_datas_output_unit():
    """Table 5's note said 'moved by 5000 V' for a calibration in ADC counts."""
    cv = {"protocol": "repetitions", "methods": ["initial", "svr"], "folds": [[1, 2]],
          "records": [], "settings": {"units": {"load": "gf", "output": "count"}},
          "gross_error": {"spec": {"axis": "x", "repetition": 1, "point": 3, "offset": 5000},
                          "records": [], "omega": []}}
    assert "moved by 5000 count (Section 4.4)" in _text(gross_tables(cv))


def test_the_terminals_table_5_gives_the_offset_in_the_datas_output_unit_too():
    from fsdecouple.reporting.console import gross_tables as terminal_tables

    recs = [{"round": 1, "test_set": t, "method": m, "axis": "x", "metric": "gamma", "value": 0.001}
            for t in (1, 2) for m in ("initial", "svr")]
    cv = {"protocol": "repetitions", "methods": ["initial", "svr"], "folds": [[1, 2]],
          "records": recs,
          "settings": {"units": {"load": "gf", "output": "count"}},
          "gross_error": {"spec": {"axis": "x", "repetition": 1, "point": 3, "offset": 5000},
                          "records": recs, "omega": [],
                          "rounds_affected": [1]}}
    title = terminal_tables(cv)[0].title
    assert "moved by +5000 count in the training data" in title
