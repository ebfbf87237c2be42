"""The Dask engine's dataset path without a cluster: its graph, and how it counts statuses.

Quick (no worker processes); the outputs themselves are compared with the local
engine's on a real cluster in test_batch_dask.py.
"""

from __future__ import annotations

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest
from test_batch import make_logs

pytest.importorskip("distributed")
pytest.importorskip("dask.dataframe")


def test_a_dataset_is_one_fused_task_per_part(sample_model, tmp_path):
    """read, decouple and write of a part are one task: unfused (Client.compute does not
    fuse, dask/distributed#8833) each part is four tasks and its frames wait in memory."""
    from fsdecouple.logs.dask_engine import _dataset_graph
    from fsdecouple.logs.jobs import ApplySpec
    from fsdecouple.logs.many import find_jobs

    logs = make_logs(tmp_path)
    jobs, _ = find_jobs([logs / "ds"])
    graph = _dataset_graph(ApplySpec(str(sample_model)), jobs[0], tmp_path / "out")
    keys = list(graph.__dask_graph__())
    assert len(jobs[0].parts) == 3
    assert len(keys) == 3  # a task per part: read, decouple and write_part fused
    parts = {k[0] for k in keys if k[0].startswith("read_parquet")}
    assert len(parts) == 1 and {"decouple_partition", "write_part"} <= set(parts.pop().split("-"))


def test_status_counts_from_footers_and_from_the_rows(tmp_path, monkeypatch):
    """Row groups of one status are counted from their statistics; the others, and a part
    written without statistics, by reading the column; the same counts either way."""
    from fsdecouple.logs.apply import STATUSES
    from fsdecouple.logs.dask_engine import _count_written

    groups = [["ok"] * 5, ["ok", "saturated", "missing", "ok"], ["extrapolated"] * 3]
    status = pa.array(sum(groups, []), pa.string())
    table = pa.table({"fx": pa.array(range(len(status)), pa.float64()), "status": status})
    with pq.ParquetWriter(tmp_path / "part.0.parquet", table.schema) as w:
        at = 0
        for g in groups:
            w.write_table(table.slice(at, len(g)))
            at += len(g)
    pq.write_table(table.slice(5, 4), tmp_path / "part.1.parquet", write_statistics=False)
    read = []
    real = pq.ParquetFile.read_row_groups

    def spy(self, row_groups, *args, **kwargs):
        read.append(list(row_groups))
        return real(self, row_groups, *args, **kwargs)

    monkeypatch.setattr(pq.ParquetFile, "read_row_groups", spy)
    rows, counts = _count_written(tmp_path)
    everything = pa.concat_arrays([status, status.slice(5, 4)])
    expected = dict.fromkeys(STATUSES, 0)
    for entry in pc.value_counts(everything).to_pylist():
        expected[entry["values"]] = entry["counts"]
    assert counts == expected and rows == len(everything) == 16
    assert counts["ok"] == 9 and counts["extrapolated"] == 3
    assert read == [[1], [0]]  # the mixed group of part 0; part 1, which has no statistics
