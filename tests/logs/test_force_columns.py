"""apply's force columns never collide with a log's own columns (issue 22)."""

from __future__ import annotations

import csv

import pytest
from conftest import invoke

from fsdecouple.logs.apply import force_columns


@pytest.mark.parametrize(("header", "want"), [
    (["ux", "uy", "uz"], ["fx", "fy", "fz"]),
    (["t", "ux", "uy", "uz", "fx"], ["decoupled_fx", "fy", "fz"]),
    (["FX", "decoupled_fx", "ux"], ["decoupled_decoupled_fx", "fy", "fz"]),
])
def test_force_columns_take_a_prefix_while_the_log_has_the_name_in_any_case(header, want):
    got = force_columns(("fx", "fy", "fz"), header)
    assert list(got) == want
    assert not {g.lower() for g in got} & {h.lower() for h in header}


def test_a_log_with_its_own_fx_column_keeps_it_and_gets_decoupled_fx(tmp_path, sample_model):
    log = tmp_path / "log.csv"
    log.write_text("t,ux,uy,uz,fx\n0,0.1,0.2,0.3,1\n")
    out = tmp_path / "out.csv"
    invoke(["apply", sample_model, log, "-o", out])
    with out.open(newline="") as fh:
        header, row = list(csv.reader(fh))[:2]
    assert header == ["t", "ux", "uy", "uz", "fx", "decoupled_fx", "fy", "fz", "status"]
    assert row[4] == "1"  # the log's own column passed through untouched
