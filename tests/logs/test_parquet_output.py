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



def test_an_infinite_reading_in_a_parquet_log_is_told_as_a_number(sim_model_file, tmp_path):
    """A Parquet log's inf was quoted as numpy's repr, 'np.float64(inf)'."""
    from conftest import assert_one_line_error, invoke

    log = pd.read_csv(SAMPLE / "task_voltages.csv").head(10)
    log.loc[4, "uy"] = np.inf
    log.to_parquet(tmp_path / "i.parquet")
    r = invoke(["apply", sim_model_file, tmp_path / "i.parquet", "-o", tmp_path / "o.csv"], 2)
    assert_one_line_error(r, "i.parquet", "column 'uy'", "is inf, expected a finite number")
    assert "np." not in r.stderr and not (tmp_path / "o.csv").exists()
