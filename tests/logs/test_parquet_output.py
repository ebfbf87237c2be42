"""`apply`'s Parquet output: how its columns are stored, and that it reads back intact.

Measured doubles seldom repeat and do not compress, so ParquetSink writes floating-point
columns plain and uncompressed (benchmarks/run.py rows 3c and 3h: dictionary encoding
and Snappy on them cost more than the whole decoupling).  The file must still read back
in pandas and pyarrow with the input's values and dtypes, and the forces eq. (11) gives.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import SAMPLE

from fsdecouple import load_model
from fsdecouple.logs.apply import apply_file

DICTIONARY = {"PLAIN_DICTIONARY", "RLE_DICTIONARY"}


def _log(path, n=5000):
    """A Parquet log of the sample task voltages: a float time, an int and a text column."""
    u = pd.read_csv(SAMPLE / "task_voltages.csv")[["ux", "uy", "uz"]].to_numpy()
    u = np.resize(u, (n, 3))
    frame = pd.DataFrame({"t": np.arange(n) / 1000.0, "ux": u[:, 0], "uy": u[:, 1],
                          "uz": u[:, 2], "sample": np.arange(n, dtype=np.int64),
                          "note": ["a", "b"] * (n // 2)})
    pq.write_table(pa.Table.from_pandas(frame, preserve_index=False), path)
    return frame


def test_float_columns_are_written_plain_and_the_file_reads_back(sample_model, tmp_path):
    model = load_model(sample_model)  # conftest's: the suite's one sample fit
    log, out = tmp_path / "log.parquet", tmp_path / "f.parquet"
    frame = _log(log)
    apply_file(model, log, out)
    meta = pq.ParquetFile(out).metadata
    schema = pq.ParquetFile(out).schema_arrow
    floats = [f.name for f in schema if pa.types.is_floating(f.type)]
    assert floats == ["t", "ux", "uy", "uz", "fx", "fy", "fz"]
    for g in range(meta.num_row_groups):
        group = meta.row_group(g)
        columns = {group.column(i).path_in_schema: group.column(i) for i in range(group.num_columns)}
        for name in floats:
            assert not DICTIONARY & set(columns[name].encodings), (name, columns[name].encodings)
            assert columns[name].compression == "UNCOMPRESSED", name
        # the few statuses repeat: dictionary-encoded, as pyarrow's default
        assert DICTIONARY & set(columns["status"].encodings)
    back = pd.read_parquet(out)
    pd.testing.assert_frame_equal(back[list(frame.columns)], frame)  # values and dtypes
    f = model.decouple(frame[["ux", "uy", "uz"]].to_numpy())
    np.testing.assert_allclose(back[["fx", "fy", "fz"]].to_numpy(), f, rtol=0, atol=1e-9)
    assert pq.read_table(out).column("status").type == pa.string()



@pytest.mark.parametrize("chunk_rows, end", [(64, "\n"), (1 << 20, "\n"), (64, "")])
@pytest.mark.parametrize("sep, decimal", [(",", "."), (";", ",")])
def test_a_csv_logs_outputs_are_doubles_in_parquet_output(sample_model, tmp_path, chunk_rows,
                                                           end, sep, decimal):
    """A CSV log's ux, uy, uz became strings in Parquet output ('0,0143' with a decimal
    comma): the columns the model reads are written as the numbers read, a missing cell
    null; the other columns keep their text."""
    model = load_model(sample_model)
    text = (SAMPLE / "task_voltages.csv").read_text().splitlines()
    rows = [f"{line}{sep if sep != ',' else ','}{'x' if i % 2 else 'y'}" for i, line in
            enumerate(text[1:])]
    rows = [r.replace(",", sep) if sep != "," else r for r in rows]
    if decimal == ",":
        rows = [r.replace(".", ",") for r in rows]
    rows[5] = sep.join(["" if j == 2 else c for j, c in enumerate(rows[5].split(sep))])  # uy
    log = tmp_path / "log.csv"
    # end "": the last line has no line end (a log still being written): no forces, its
    # numbers kept in the same double column
    log.write_text("\n".join([sep.join([*text[0].split(","), "note"]), *rows]) + end)
    settings = None
    if sep != ",":
        cfg = tmp_path / "c.yaml"
        cfg.write_text(f'csv: {{sep: "{sep}", decimal: "{decimal}"}}\n')
        from fsdecouple import load_config
        settings = load_config(cfg)
    out = tmp_path / "f.parquet"
    apply_file(model, log, out, settings=settings, chunk_rows=chunk_rows)
    back = pq.read_table(out)
    want = pd.read_csv(SAMPLE / "task_voltages.csv")
    for c in ("ux", "uy", "uz"):
        assert back.column(c).type == pa.float64(), c
    got = back.column("uy").to_numpy(zero_copy_only=False)
    assert np.isnan(got[5]) and back.column("uy").null_count == 1
    np.testing.assert_array_equal(np.delete(got, 5), np.delete(want["uy"].to_numpy(), 5))
    np.testing.assert_array_equal(back.column("ux").to_numpy(), want["ux"].to_numpy())
    assert back.column("note").type == pa.string() and back.column("note")[1].as_py() == "x"


def test_an_infinite_reading_in_a_parquet_log_is_told_as_a_number(sim_model_file, tmp_path):
    """A Parquet log's inf was quoted as numpy's repr, 'np.float64(inf)'."""
    from conftest import assert_one_line_error, invoke

    log = pd.read_csv(SAMPLE / "task_voltages.csv").head(10)
    log.loc[4, "uy"] = np.inf
    log.to_parquet(tmp_path / "i.parquet")
    r = invoke(["apply", sim_model_file, tmp_path / "i.parquet", "-o", tmp_path / "o.csv"], 2)
    assert_one_line_error(r, "i.parquet", "column 'uy'", "is inf, expected a finite number")
    assert "np." not in r.stderr and not (tmp_path / "o.csv").exists()


@pytest.mark.parametrize("dtype", [np.int64, np.uint64])
def test_integer_outputs_beyond_2_53_are_read_as_a_csv_reads_them(sample_model, tmp_path, dtype):
    """Whole counts in an integer column: Arrow's safe cast to double refused 2**60 with a
    71-line traceback; the CSV reader rounds such a number and its row is not_finite."""
    model = load_model(sample_model)
    n = 300
    u = np.zeros((n, 3), dtype=dtype)
    u[:, 0] = 1
    u[150, 0] = 2 ** 60
    log, out = tmp_path / "counts.parquet", tmp_path / "f.csv"
    pq.write_table(pa.table({"ux": u[:, 0], "uy": u[:, 1], "uz": u[:, 2]}), log)
    summary = apply_file(model, log, out)
    assert summary.status_counts["not_finite"] == 1 and summary.status_counts["ok"] == n - 1
    forces = pd.read_csv(out)
    assert forces["status"][150] == "not_finite" and np.isfinite(forces["fx"][0])


def test_a_csv_output_quotes_header_names_that_hold_its_separator_or_quotes(sample_model, tmp_path):
    """A Parquet log's column 'time,s' made apply's CSV header one field longer than its rows."""
    model = load_model(sample_model)
    frame = pd.read_csv(SAMPLE / "task_voltages.csv").head(400)
    frame.columns = ["time,s", "ux", "uy", "uz"]
    frame['say "hi"'] = 1.0
    log, out = tmp_path / "q.parquet", tmp_path / "f.csv"
    pq.write_table(pa.Table.from_pandas(frame, preserve_index=False), log)
    apply_file(model, log, out)
    back = pd.read_csv(out)
    assert list(back.columns) == ["time,s", "ux", "uy", "uz", 'say "hi"', "fx", "fy", "fz", "status"]
    assert back["time,s"].tolist() == frame["time,s"].tolist()
