"""apply reads the layouts fit reads: unnamed columns, repeated names and a side table
are not passed through, and a warning says so (issue 25, item 5)."""

from __future__ import annotations

import csv
import io

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import SAMPLE, invoke

from fsdecouple.core.modelfile import load_model
from fsdecouple.logs.apply import apply_file
from fsdecouple.logs.passthrough import passed_columns
from fsdecouple.logs.reader import CsvParser

LOG = SAMPLE / "task_voltages.csv"


@pytest.fixture(scope="module")
def model(sample_model):
    return load_model(sample_model)


def rows_of(path):
    return list(csv.reader(io.StringIO(path.read_text(encoding="utf-8"), newline="")))


def side_table_log(path, rows=200, *, quote=False, blank=False, eol="\n"):
    """The task log with an unnamed column, then a side table, as a spreadsheet saves it."""
    src = rows_of(LOG)[: rows + 1]
    out = io.StringIO()
    w = csv.writer(out, lineterminator=eol)
    w.writerow([*src[0], "", "note", "load plan"])
    for i, r in enumerate(src[1:]):
        note = 'a, "quoted" note' if quote and i == 7 else f"n{i}"
        w.writerow([*r, "", note, str(i)])
        if blank and i == 50:
            out.write(eol)
    path.write_bytes(out.getvalue().encode())
    return path


def expected_cells(path):
    """Every row's cells left of the unnamed column, read independently by the csv module."""
    rows = rows_of(path)
    return [r[:4] if r else ["", "", "", ""] for r in rows]


@pytest.mark.parametrize(("header", "mapped", "keep"), [
    (["t", "ux", "uy", "uz"], ["ux", "uy", "uz"], [0, 1, 2, 3]),
    (["t", "ux", "uy", "uz", "", "", "a", "b"], ["ux", "uy", "uz"], [0, 1, 2, 3]),
    # a mapped column right of the gap: not a side table, only the unnamed column goes
    (["t", "", "ux", "uy", "uz", "a"], ["ux", "uy", "uz"], [0, 2, 3, 4, 5]),
    (["a", "ux", "a", "uy", "uz"], ["ux", "uy", "uz"], [1, 3, 4]),
    # a name repeated only in the side table: the data's own column stays
    (["t", "ux", "uy", "uz", "", "t"], ["ux", "uy", "uz"], [0, 1, 2, 3]),
])
def test_passed_columns(header, mapped, keep):
    got, dropped = passed_columns(header, mapped)
    assert got == keep
    assert sorted(got + [d.column - 1 for d in dropped]) == list(range(len(header)))


@pytest.mark.parametrize("variant", ["fast", "quoted", "blank", "crlf", "small-blocks"])
def test_side_table_dropped_every_row_kept(tmp_path, model, variant, monkeypatch):
    if variant in ("fast", "crlf", "small-blocks"):  # the lines are cut without the csv module
        monkeypatch.setattr(CsvParser, "exact", lambda *a: pytest.fail("line-by-line parse"))
    log = side_table_log(tmp_path / "log.csv", quote=variant == "quoted", blank=variant == "blank",
                         eol="\r\n" if variant == "crlf" else "\n")
    out = tmp_path / "out.csv"
    summary = apply_file(model, log, out, chunk_rows=7 if variant == "small-blocks" else 1 << 20)
    assert [(d.column, d.name) for d in summary.dropped] == [(5, ""), (6, "note"), (7, "load plan")]
    got = rows_of(out)
    assert got[0] == ["t", "ux", "uy", "uz", "fx", "fy", "fz", "status"]
    want = expected_cells(log)
    assert len(got) == len(want) == summary.rows + 1
    assert [r[:4] for r in got[1:]] == want[1:]
    # the forces are those of the log without the side table
    plain = tmp_path / "plain.csv"
    plain.write_text("".join(",".join(r) + "\n" for r in want))
    apply_file(model, plain, tmp_path / "plain_out.csv")
    assert got == rows_of(tmp_path / "plain_out.csv")


def test_bytes_of_kept_fields_pass_through(tmp_path, model):
    log = tmp_path / "log.csv"
    body = b"t,ux,uy,uz,,x\n" + b"caf\xe9,0.01,0.02,0.03,,1\n" * 3 + b'"a,b",0.01,0.02,0.03,,2\n'
    log.write_bytes(body)
    out = tmp_path / "out.csv"
    apply_file(model, log, out)
    lines = out.read_bytes().splitlines()
    assert lines[0] == b"t,ux,uy,uz,fx,fy,fz,status"
    assert lines[1].startswith(b"caf\xe9,0.01,0.02,0.03,")
    assert lines[4].startswith(b'"a,b",0.01,0.02,0.03,')


@pytest.mark.parametrize("source", ["csv", "parquet"])
def test_parquet_output_has_only_named_columns(tmp_path, model, source):
    log = side_table_log(tmp_path / "log.csv", rows=20)
    if source == "parquet":
        rows = expected_cells(log)
        table = pa.table([pa.array([float(r[0]) for r in rows[1:]]),
                          *[pa.array([float(r[k]) for r in rows[1:]]) for k in (1, 2, 3)],
                          pa.array(["x"] * 20)], names=["t", "ux", "uy", "uz", ""])
        log = tmp_path / "log.parquet"
        pq.write_table(table, log)
    out = tmp_path / "out.parquet"
    summary = apply_file(model, log, out)
    names = pq.read_schema(out).names
    assert names == ["t", "ux", "uy", "uz", "fx", "fy", "fz", "status"]
    assert summary.dropped and all(d.name not in names for d in summary.dropped)
    assert len(pq.read_table(out)) == 20


def test_cli_warns_and_json_lists_the_dropped_columns(tmp_path, sample_model):
    log = side_table_log(tmp_path / "log.csv", rows=10)
    r = invoke(["apply", sample_model, log, "-o", tmp_path / "out.csv"])
    assert "not passed through" in r.stderr and "'note'" in r.stderr and "side table" in r.stderr
    r = invoke(["apply", sample_model, log, "-o", tmp_path / "out2.csv", "--json"])
    import json

    doc = json.loads(r.stdout)
    assert [d["column"] for d in doc["dropped_columns"]] == [5, 6, 7]


def test_a_log_without_dropped_columns_is_passed_through_byte_for_byte(tmp_path, model):
    out = tmp_path / "out.csv"
    summary = apply_file(model, LOG, out)
    assert summary.dropped == []
    src = LOG.read_bytes().splitlines()
    got = out.read_bytes().splitlines()
    assert all(g.startswith(s + b",") for s, g in zip(src, got, strict=True))
    assert np.isfinite(summary.offsets).all()
