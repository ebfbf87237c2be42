"""Many-log apply on a real Dask cluster (issue 16): two worker processes on small data.

Every output is compared with the local engine's (itself single-file ``apply``,
test_batch.py): CSV byte for byte, Parquet as Arrow tables, every column and type.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import signal
import socket
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import SAMPLE, assert_one_line_error, invoke
from test_batch import SIX_MODEL, make_logs, make_six_axis_logs, spoil

distributed = pytest.importorskip("distributed")

pytestmark = pytest.mark.slow  # a cluster of worker processes


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0", silence_logs=50) as c:
        yield c


def _tables_equal(a, b):
    ta, tb = pq.read_table(a), pq.read_table(b)
    assert ta.schema.equals(tb.schema, check_metadata=False), (ta.schema, tb.schema)
    assert ta.equals(tb)
    # the pandas metadata too: Dask's said double[pyarrow], so pandas read other dtypes
    for key in (b"fsdecouple.force_unit", b"fsdecouple.output_unit", b"pandas"):
        assert ta.schema.metadata[key] == tb.schema.metadata[key], key


def _same_outputs(local, dask):
    files = sorted(p.relative_to(local) for p in local.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(dask) for p in dask.rglob("*") if p.is_file())
    for rel in files:
        if rel.suffix == ".csv":
            assert (local / rel).read_bytes() == (dask / rel).read_bytes(), rel
        else:
            _tables_equal(local / rel, dask / rel)
    return files


def test_dask_writes_what_the_local_engine_writes(sample_model, tmp_path, cluster):
    logs = make_logs(tmp_path)
    args = ["apply", sample_model, logs, "--tare", 200, "--unit", "gf", "--json"]
    local = json.loads(invoke([*args, "-o", f"{tmp_path / 'local'}/"]).stdout)
    dask = json.loads(invoke([*args, "-o", f"{tmp_path / 'dask'}/", "--engine", "dask",
                              "--scheduler", cluster.scheduler_address]).stdout)
    files = _same_outputs(tmp_path / "local", tmp_path / "dask")
    assert len(files) == 6  # two CSV logs, three dataset parts, one Parquet log
    strip = [{k: v for k, v in f.items() if k != "output"} for f in local["files"]]
    assert strip == [{k: v for k, v in f.items() if k != "output"} for f in dask["files"]]
    assert dask["engine"] == "dask" and dask["failed"] == []
    assert {f["rows"] for f in dask["files"]} == {1000, 3000}


def test_dask_writes_every_component_of_a_six_axis_model(tmp_path, cluster):
    """Forces and moments (mixed units), a dataset tared across its parts: as the local engine."""
    logs = make_six_axis_logs(tmp_path)
    args = ["apply", SIX_MODEL, logs, "--tare", 200]
    invoke([*args, "-o", f"{tmp_path / 'local'}/"])
    invoke([*args, "-o", f"{tmp_path / 'dask'}/", "--engine", "dask",
            "--scheduler", cluster.scheduler_address])
    _same_outputs(tmp_path / "local", tmp_path / "dask")
    assert {"mx", "my", "mz"} <= set(pq.read_table(tmp_path / "dask" / "ds").column_names)


def test_dask_local_cluster_of_its_own_and_bad_logs(sample_model, tmp_path):
    """Without --scheduler: a LocalCluster of --workers processes.  A bad CSV log and a
    dataset whose part lacks a column fail alone; nothing of them is written."""
    logs = spoil(make_logs(tmp_path))
    out = tmp_path / "out"
    # one worker process: a second would cost its start-up and prove nothing more here
    r = invoke(["apply", sample_model, logs, "-o", f"{out}/", "--engine", "dask", "--workers", 1,
                "--json"], code=2)
    doc = json.loads(r.stdout)
    assert doc["failed"] == [str(logs / "b" / "two.csv"), str(logs / "ds")]
    assert "two.csv, row 6, column 'uy'" in r.stderr and "part.3.parquet: columns" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 2, r.stderr  # no worker tracebacks
    assert sorted(p.name for p in out.iterdir()) == ["a", "single.parquet"]
    ref = tmp_path / "ref.csv"
    invoke(["apply", sample_model, logs / "a" / "one.csv", "-o", ref])
    assert (out / "a" / "one.csv").read_bytes() == ref.read_bytes()


def test_our_local_cluster_keeps_glibcs_malloc_thresholds(monkeypatch):
    """Dask's nannies set MALLOC_TRIM_THRESHOLD_, which turns off glibc's dynamic mmap
    threshold (a page fault per 4 KiB of every array over 128 KiB); our workers go without."""
    from fsdecouple.logs.dask_engine import dask_client

    # an earlier LocalCluster of this process wrote it into os.environ (the nanny does)
    monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_", raising=False)
    with dask_client(workers=1) as client:
        env = client.run(lambda: {k: os.environ.get(k) for k in ("MALLOC_TRIM_THRESHOLD_",
                                                                 "OMP_NUM_THREADS")})
    assert list(env.values()) == [{"MALLOC_TRIM_THRESHOLD_": None, "OMP_NUM_THREADS": "1"}]


@pytest.mark.parametrize("answer", [b"HTTP/1.1 400 Bad Request\r\n\r\n", None],
                         ids=["another-service", "silent-listener"])
def test_an_address_where_no_scheduler_answers_is_one_line(sample_model, tmp_path, monkeypatch,
                                                           answer):
    """Another service (its reply read as a message length: 3 EiB, a MemoryError
    traceback), or a listener that never answers (distributed waits for its handshake
    without a deadline: apply hung): one line, exit 2, in bounded time."""

    import fsdecouple.logs.dask_engine as engine

    monkeypatch.setattr(engine, "CONNECT_TIMEOUT", 1.0)
    logs = make_logs(tmp_path)
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()
    port, held = server.getsockname()[1], []

    def serve():
        with contextlib.suppress(OSError):
            while True:
                conn, _ = server.accept()
                held.append(conn)
                if answer is not None:
                    conn.sendall(answer)

    threading.Thread(target=serve, daemon=True).start()
    try:
        t0 = time.monotonic()
        r = invoke(["apply", sample_model, logs, "-o", f"{tmp_path / 'out'}/", "--engine", "dask",
                    "--scheduler", f"tcp://127.0.0.1:{port}"], code=2)
        assert time.monotonic() - t0 < 30
    finally:
        server.close()
        for conn in held:
            conn.close()
    assert_one_line_error(r, f"--scheduler tcp://127.0.0.1:{port}: cannot connect")
    assert not (tmp_path / "out").exists()


def test_unreachable_scheduler_is_one_line(sample_model, tmp_path, monkeypatch):
    import fsdecouple.logs.dask_engine as engine

    monkeypatch.setattr(engine, "CONNECT_TIMEOUT", 2.0)
    logs = make_logs(tmp_path)
    with socket.socket() as s:  # a port on this machine that nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    t0 = time.monotonic()
    r = invoke(["apply", sample_model, logs, "-o", f"{tmp_path / 'out'}/", "--engine", "dask",
                "--scheduler", f"tcp://127.0.0.1:{port}"], code=2)
    assert time.monotonic() - t0 < 30
    assert_one_line_error(r, f"--scheduler tcp://127.0.0.1:{port}: cannot connect")
    assert not (tmp_path / "out").exists()


def test_a_worker_killed_mid_log_leaves_no_partial_output(sample_model, tmp_path, cluster):
    """A log read from a FIFO: the test feeds it in part (output is being written), kills
    the worker decoupling it with SIGKILL, then feeds the whole log to the task Dask runs
    again.  The output is the whole log's, as the local engine writes it, and the killed
    worker's partial file is gone."""
    from fsdecouple.logs.many import apply_many

    rows = (SAMPLE / "task_voltages.csv").read_bytes().splitlines(keepends=True)
    body = b"".join(rows[1:]) * 150  # 450,000 rows, ~17 MB: four 4 MB blocks
    content = rows[0] + body
    (tmp_path / "src").mkdir()
    regular = tmp_path / "src" / "log.csv"
    regular.write_bytes(content)
    fifo = tmp_path / "fifo" / "log.csv"
    fifo.parent.mkdir()
    os.mkfifo(fifo)
    out = tmp_path / "out"
    result = {}
    run = threading.Thread(target=lambda: result.update(r=apply_many(
        sample_model, [fifo], out, engine="dask", scheduler=cluster.scheduler_address)))
    with distributed.Client(cluster, set_as_default=False) as client:
        run.start()
        fh = _wait_for(lambda: _open_writer(fifo))  # once the task opens the FIFO
        try:
            # two blocks and a half: apply writes block 1 once block 2 is read
            fh.write(content[:10_000_000])
            fh.flush()
            partial = _wait_for(lambda: [p for p in out.rglob(".*.tmp") if p.stat().st_size > 0])
            busy = [w for w, keys in client.processing().items() if keys]
            assert len(busy) == 1, client.processing()
            pid = client.run(os.getpid, workers=busy)[busy[0]]
            os.kill(pid, signal.SIGKILL)  # as the OOM killer or a lost node would
        finally:
            # at once: the task run again must not open the FIFO while this end is open, or
            # it reads what the killed reader left in the pipe and the log ends there
            with contextlib.suppress(BrokenPipeError):  # the killed reader is gone
                fh.close()
        _wait_for(lambda: busy[0] not in client.scheduler_info()["workers"])
        with _wait_for(lambda: _open_writer(fifo)) as fh:  # the task, run again on a live worker
            fh.write(content)
        run.join(60)
        assert not run.is_alive()
        client.wait_for_workers(2, timeout=60)
    assert partial and not any(p.exists() for p in partial)
    doc = result["r"].to_dict()
    assert doc["failed"] == [] and doc["files"][0]["rows"] == 450_000
    ref = tmp_path / "ref.csv"
    invoke(["apply", sample_model, regular, "-o", ref])
    assert (out / "log.csv").read_bytes() == ref.read_bytes()
    assert sorted(p.name for p in out.iterdir()) == ["log.csv"]  # no staging, no temporary file


def _wait_for(check, timeout=60.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        got = check()
        if got:
            return got
        time.sleep(0.05)
    raise AssertionError("timed out")


def test_a_worker_killed_on_every_try_fails_the_log_alone(sample_model, tmp_path, cluster,
                                                         monkeypatch):
    """With no retry allowed (allowed-failures 0), the one death of the worker decoupling a
    log is its last: the log is reported failed in one line, its partial output is gone,
    and the other log of the run is written.  (On the module's cluster, its scheduler
    allowing no failure for this test: it reads ``allowed_failures`` at each worker's
    death, as a cluster started under ``distributed.scheduler.allowed-failures: 0`` does;
    a cluster of its own cost two more worker processes, ~2.5 s of CPU.)"""
    from fsdecouple.logs.many import apply_many

    rows = (SAMPLE / "task_voltages.csv").read_bytes().splitlines(keepends=True)
    content = rows[0] + b"".join(rows[1:]) * 150  # ~17 MB: four 4 MB blocks
    logs = tmp_path / "logs"
    logs.mkdir()
    fifo = logs / "dies.csv"
    os.mkfifo(fifo)
    (logs / "good.csv").write_bytes(b"".join(rows[:1001]))
    out = tmp_path / "out"
    result = {}
    monkeypatch.setattr(cluster.scheduler, "allowed_failures", 0)
    with distributed.Client(cluster, set_as_default=False) as client:
        run = threading.Thread(target=lambda: result.update(r=apply_many(
            sample_model, [fifo, logs / "good.csv"], out, engine="dask",
            scheduler=cluster.scheduler_address)))
        run.start()
        fh = _wait_for(lambda: _open_writer(fifo))  # once the task opens the FIFO
        try:
            fh.write(content[:10_000_000])  # apply writes block 1 once block 2 is read
            fh.flush()
            partial = _wait_for(lambda: [p for p in out.rglob(".*.tmp") if p.stat().st_size > 0])
            _wait_for(lambda: (out / "good.csv").exists())  # the other log is done
            busy = [w for w, keys in client.processing().items() if keys]
            assert len(busy) == 1, client.processing()
            pid = client.run(os.getpid, workers=busy)[busy[0]]
            os.kill(pid, signal.SIGKILL)
            run.join(60)
        finally:
            with contextlib.suppress(BrokenPipeError):
                fh.close()
        assert not run.is_alive()
        client.wait_for_workers(2, timeout=60)  # the nanny's new worker, for the tests after
    doc = result["r"].to_dict()
    assert doc["failed"] == [str(fifo)]
    error = next(f["error"] for f in doc["files"] if f["input"] == str(fifo))
    assert "dies.csv: Dask workers died while decoupling it" in error and "nothing written" in error
    assert "\n" not in error
    assert partial and not any(p.exists() for p in partial)
    assert sorted(p.name for p in out.iterdir()) == ["good.csv"]  # no staging, nothing partial
    ref = tmp_path / "ref.csv"
    invoke(["apply", sample_model, logs / "good.csv", "-o", ref])
    assert (out / "good.csv").read_bytes() == ref.read_bytes()


def _open_writer(fifo):
    """The FIFO's writing end once a reader has it open, else None (never blocks)."""
    try:
        fd = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
    except OSError as err:
        if err.errno == errno.ENXIO:  # no reader yet
            return None
        raise
    os.set_blocking(fd, True)
    return os.fdopen(fd, "wb")


def test_a_hive_partitioned_dataset_reads_back_whole_from_both_engines(sample_model, tmp_path, cluster):
    """robot=A/ and robot=B/ parts: no partition column inside the files written (Dask's
    was a dictionary whose index width varied by part, so no reader could merge them),
    and each engine's output reads back whole with pandas, pyarrow and Dask."""
    import dask.dataframe as dd
    import pandas as pd

    volts = pd.read_csv(SAMPLE / "task_voltages.csv")
    for i, robot in enumerate(["A", "B", "C"]):
        part = tmp_path / "fleet" / f"robot={robot}" / "part.0.parquet"
        part.parent.mkdir(parents=True)
        pq.write_table(pa.Table.from_pandas(volts.iloc[i * 700:(i + 1) * 700], preserve_index=False), part)
    args = ["apply", sample_model, tmp_path / "fleet", "--tare", 200]
    invoke([*args, "-o", f"{tmp_path / 'local'}/"])
    invoke([*args, "-o", f"{tmp_path / 'dask'}/", "--engine", "dask",
            "--scheduler", cluster.scheduler_address])
    _same_outputs(tmp_path / "local", tmp_path / "dask")
    whole, dtypes = {}, {}
    for engine in ("local", "dask"):
        out = tmp_path / engine
        for part in out.rglob("*.parquet"):
            assert "robot" not in pq.read_schema(part).names, part
            # each column encoded as apply's ParquetSink encodes it (sinks.parquet_options):
            # floats plain and uncompressed, the status dictionary-encoded with Snappy
            group = pq.ParquetFile(part).metadata.row_group(0)
            stored = {group.column(i).path_in_schema: group.column(i) for i in range(group.num_columns)}
            for name in ("ux", "fx"):
                assert stored[name].compression == "UNCOMPRESSED", (engine, name)
                assert not {"PLAIN_DICTIONARY", "RLE_DICTIONARY"} & set(stored[name].encodings)
            assert stored["status"].compression == "SNAPPY", engine
        with warnings.catch_warnings():  # dask's own reset_index(inplace=True), pandas >= 3.1
            warnings.filterwarnings("ignore", message="The inplace keyword")
            by_dask = dd.read_parquet(out).compute()
        readings = [pd.read_parquet(out), pq.read_table(out).to_pandas(), by_dask]
        for frame in readings:
            assert len(frame) == 2100 and sorted(set(frame["robot"].astype(str))) == ["A", "B", "C"]
            assert {"fx", "fy", "fz", "status"} <= set(frame.columns)
        whole[engine] = readings[1].sort_values(["robot", "t"]).reset_index(drop=True)
        dtypes[engine] = [str(f.dtypes.drop("robot").to_dict()) for f in readings]
    assert dtypes["local"] == dtypes["dask"]
    assert "pyarrow" not in dtypes["local"][0]  # pandas' own types, as a CSV log reads
    for c in ("fx", "fy", "fz"):
        np.testing.assert_array_equal(whole["local"][c].to_numpy(float), whole["dask"][c].to_numpy(float))


def test_dask_lists_entries_named_like_logs_that_are_not_files(sample_model, tmp_path, cluster):
    from test_batch import odd_entries

    logs = odd_entries(tmp_path)
    r = invoke(["apply", sample_model, logs, "-o", f"{tmp_path / 'out'}/", "--json", "--engine", "dask",
                "--scheduler", cluster.scheduler_address], code=2)
    doc = json.loads(r.stdout)
    assert sorted(Path(p).name for p in doc["failed"]) == ["dangling.csv", "fifo.csv", "folder.csv"]
    assert (tmp_path / "out" / "good.csv").is_file()


def test_interval_columns_from_both_engines_as_single_file_apply(sample_model, tmp_path, cluster):
    """Issue 23: ``--interval`` on many logs adds the _lo/_hi columns in both engines, the
    same bytes and Arrow tables as single-file apply; a log with the sensor's own ``FX``
    reading gets ``decoupled_fx`` and ``decoupled_fx_lo`` from Dask too (it wrote ``fx``)."""
    import pandas as pd

    logs = make_logs(tmp_path)
    for part in (logs / "ds").glob("*.parquet"):
        t = pq.read_table(part)
        pq.write_table(t.append_column("FX", t.column("ux")), part)
    args = ["apply", sample_model, logs, "--tare", 200, "--interval", 0.9, "--json"]
    invoke([*args, "-o", f"{tmp_path / 'local'}/"])
    invoke([*args, "-o", f"{tmp_path / 'dask'}/", "--engine", "dask",
            "--scheduler", cluster.scheduler_address])
    _same_outputs(tmp_path / "local", tmp_path / "dask")
    one = tmp_path / "one.csv"
    invoke(["apply", sample_model, logs / "a" / "one.csv", "-o", one, "--tare", 200,
            "--interval", 0.9])
    assert one.read_bytes() == (tmp_path / "dask" / "a" / "one.csv").read_bytes()
    ds = pd.read_parquet(tmp_path / "dask" / "ds")
    assert {"decoupled_fx", "decoupled_fx_lo", "decoupled_fx_hi", "fz_hi"} <= set(ds.columns)
    assert (ds["decoupled_fx_lo"] < ds["decoupled_fx"]).all()
    assert (ds["decoupled_fx"] < ds["decoupled_fx_hi"]).all()


def test_a_local_cluster_that_cannot_start_is_one_line(sample_model, tmp_path, monkeypatch):
    """A LocalCluster whose worker processes cannot start (no process may be spawned, a
    scratch directory of another user) raised "Nanny failed to start": a traceback."""
    def no_cluster(*a, **k):
        raise RuntimeError("Nanny failed to start.")

    monkeypatch.setattr(distributed, "LocalCluster", no_cluster)
    r = invoke(["apply", sample_model, SAMPLE / "task_voltages.csv", "-o", f"{tmp_path / 'out'}/",
                "--engine", "dask"], code=2)
    assert_one_line_error(r, "--engine dask", "cannot start a local cluster", "--engine local")
    assert not (tmp_path / "out").exists() or list((tmp_path / "out").iterdir()) == []
