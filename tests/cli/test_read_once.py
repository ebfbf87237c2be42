"""Inputs that can be read once (FIFOs), bytes that are not UTF-8, and Parquet nested columns.

docs/errors.md, "Errors and exit codes": a FIFO gets FIFO_WAIT seconds to deliver its
first bytes; the header of a CSV log must be UTF-8, its data lines are bytes that
CSV output passes through unchanged, and Parquet output refuses (naming row and
column) any that are not UTF-8, whatever the block; a Parquet log's list, struct
or map column passes through to Parquet, is refused for CSV output.
"""

from __future__ import annotations

import os
import threading

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import SAMPLE, assert_one_line_error, invoke

from fsdecouple.errors import InputError
from fsdecouple.files import inputs

LOG = SAMPLE / "task_voltages.csv"


# --- FIFOs ---------------------------------------------------------------------------

@pytest.fixture
def short_wait(monkeypatch):
    monkeypatch.setattr(inputs, "FIFO_WAIT", 0.3)


@pytest.mark.parametrize("which", ["log", "config", "model", "calibration"])
def test_a_fifo_without_writer_is_refused_not_waited_on(tmp_path, sample_model, short_wait, which):
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    out = tmp_path / "f.csv"
    args = {"log": ["apply", sample_model, fifo],
            "config": ["apply", sample_model, LOG, "-c", fifo],
            "model": ["apply", fifo, LOG],
            "calibration": ["fit", fifo]}[which]
    r = invoke([*args, "-o", out], code=2)
    assert_one_line_error(r, "pipe.csv", "no data after 0.3 s")
    assert not out.exists() and list(tmp_path.iterdir()) == [fifo]


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_a_fifo_with_a_writer_is_read_whole(tmp_path, sample_model, short_wait):
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    data = LOG.read_bytes()

    def write():
        with open(fifo, "wb") as fh:  # blocks until apply opens the read end
            fh.write(data)

    writer = threading.Thread(target=write, daemon=True)
    writer.start()
    out = tmp_path / "f.csv"
    invoke(["apply", sample_model, fifo, "-o", out])
    writer.join(10)
    f = pd.read_csv(out, dtype=str, keep_default_na=False)
    assert len(f) == data.count(b"\n") - 1
    assert (f["status"] == "ok").all()


def test_a_parquet_log_that_is_a_fifo_is_refused_at_once(tmp_path, sample_model):
    fifo = tmp_path / "pipe.parquet"
    os.mkfifo(fifo)  # no writer: reading its footer would block for ever
    r = invoke(["apply", sample_model, fifo, "-o", tmp_path / "f.csv"], code=2)
    assert_one_line_error(r, "pipe.parquet", "must be a regular file")


# --- bytes that are not UTF-8 ----------------------------------------------------------

def _log_with_note(path, bad_row: int, rows: int = 6000, cell: bytes = b"caf\xe9"):
    """A log with a pass-through column 'note' holding ``cell`` at spreadsheet row ``bad_row``."""
    body = LOG.read_bytes().split(b"\n")[1:-1]
    lines = [b"t,ux,uy,uz,note"]
    for i in range(rows):
        lines.append(body[i % len(body)] + b"," + (cell if i + 2 == bad_row else b"ok"))
    path.write_bytes(b"\n".join(lines) + b"\n")
    return path


@pytest.mark.parametrize("row", [2, 5000])
def test_non_utf8_bytes_pass_through_to_csv_whatever_the_row(tmp_path, sample_model, row):
    log = _log_with_note(tmp_path / "log.csv", row)
    out = tmp_path / "f.csv"
    invoke(["apply", sample_model, log, "-o", out])
    lines = out.read_bytes().split(b"\n")
    assert len(lines) == 6002  # header, 6000 rows, the final line feed
    assert lines[row - 1].split(b",")[4] == b"caf\xe9"  # the bytes as they were


@pytest.mark.parametrize("row", [2, 5000])
@pytest.mark.parametrize("chunk_rows", [64, 1 << 20])
def test_non_utf8_bytes_are_refused_for_parquet_whatever_the_row(tmp_path, sample_model_obj, row,
                                                                 chunk_rows):
    from fsdecouple.errors import InputError
    from fsdecouple.logs.apply import apply_file

    log = _log_with_note(tmp_path / "log.csv", row)
    out = tmp_path / "f.parquet"
    with pytest.raises(InputError, match=rf"log.csv, row {row}, column 'note': 'caf\\xe9' is not UTF-8"):
        apply_file(sample_model_obj, log, out, chunk_rows=chunk_rows)
    assert list(tmp_path.iterdir()) == [log]


@pytest.mark.parametrize("row", [2, 5000])
def test_the_same_rule_in_small_blocks_for_csv(tmp_path, sample_model_obj, row):
    from fsdecouple.logs.apply import apply_file

    log = _log_with_note(tmp_path / "log.csv", row)
    out = tmp_path / "f.csv"
    # small blocks: row 5,000 is far from the first block, which once had its own check
    summary = apply_file(sample_model_obj, log, out, chunk_rows=64)
    assert summary.rows == 6000
    assert out.read_bytes().split(b"\n")[row - 1].split(b",")[4] == b"caf\xe9"


def test_a_non_utf8_byte_starting_row_2_is_not_taken_for_the_header(tmp_path, sample_model):
    """The header was decoded with the next byte: row 2 alone was refused for it."""
    text = LOG.read_bytes().split(b"\n")
    for first in (b"\xe9", "é".encode()):
        log = tmp_path / "log.csv"
        log.write_bytes(b"note," + text[0] + b"\n" + b"\n".join(first + b"," + t for t in text[1:-1])
                        + b"\n")
        out = tmp_path / "f.csv"
        invoke(["apply", sample_model, log, "-o", out, "--force"])
        assert out.read_bytes().split(b"\n")[1].startswith(first + b",")


def test_a_non_utf8_header_is_refused(tmp_path, sample_model):
    log = tmp_path / "log.csv"
    log.write_bytes(b"t,ux,uy,uz,temp \xb0C\n" + b"0,0.01,0.01,0.01,20\n")
    r = invoke(["apply", sample_model, log, "-o", tmp_path / "f.csv"], code=2)
    # the row, the column and the cell are named (it said the file alone)
    assert_one_line_error(r, "log.csv, row 1, column 'temp \\xb0C': 'temp \\xb0C' is not UTF-8 text")


def _sample_with_a_note(tmp_path, edit):
    """The sample set with a 'note' column added to rep3.csv, its lines then ``edit``ed
    (bytes, header first); returns the set's directory."""
    from conftest import SAMPLE

    cal = tmp_path / "cal"
    cal.mkdir()
    for r in range(1, 7):
        (cal / f"rep{r}.csv").write_bytes((SAMPLE / "calibration" / f"rep{r}.csv").read_bytes())
    lines = (cal / "rep3.csv").read_bytes().split(b"\n")
    lines[0] += b",note"
    edit(lines)
    (cal / "rep3.csv").write_bytes(b"\n".join(lines))
    return cal


def test_a_non_utf8_calibration_cell_is_named_by_row_and_column(tmp_path):
    """A spreadsheet's Latin-1 export (a date column's 'été'): the whole file was refused
    as 'not a UTF-8 text file', naming no row or column."""
    def edit(lines):
        lines[4] += b",\xe9t\xe9"

    cal = _sample_with_a_note(tmp_path, edit)
    r = invoke(["fit", cal, "-o", tmp_path / "m.json"], code=2)
    assert_one_line_error(r, "rep3.csv, row 5, column 'note': '\\xe9t\\xe9' is not UTF-8 text")
    assert not (tmp_path / "m.json").exists()


def test_a_non_utf8_voltage_is_a_bad_number_not_a_crash(tmp_path, sample_model):
    log = tmp_path / "log.csv"
    log.write_bytes(b"t,ux,uy,uz\n0,0.01\xe9,0.01,0.01\n")
    r = invoke(["apply", sample_model, log, "-o", tmp_path / "f.csv"], code=2)
    assert_one_line_error(r, "log.csv, row 2, column 'ux'", "expected a finite number")


# --- Parquet nested columns ------------------------------------------------------------

def _parquet(path, **extra):
    table = pa.Table.from_pandas(pd.read_csv(LOG), preserve_index=False)
    for name, arr in extra.items():
        if name in table.column_names:
            table = table.set_column(table.column_names.index(name), name, arr)
        else:
            table = table.append_column(name, arr)
    pq.write_table(table, path)
    return path, len(table)


NESTED = {
    "list": lambda n: pa.array([[1, 2]] * n),
    "struct": lambda n: pa.array([{"a": 1, "b": "x"}] * n),
    "map": lambda n: pa.array([[("k", 1)]] * n, pa.map_(pa.string(), pa.int64())),
}


@pytest.mark.parametrize("kind", list(NESTED))
def test_a_nested_pass_through_column_goes_to_parquet(tmp_path, sample_model, kind):
    log, n = _parquet(tmp_path / "log.parquet", tags=NESTED[kind](3000))
    out = tmp_path / "f.parquet"
    invoke(["apply", sample_model, log, "-o", out])
    table = pq.read_table(out)
    assert table.num_rows == n and table.column("tags").equals(pq.read_table(log).column("tags"))


@pytest.mark.parametrize("kind", list(NESTED))
def test_a_nested_pass_through_column_is_refused_for_csv(tmp_path, sample_model, kind):
    log, _ = _parquet(tmp_path / "log.parquet", tags=NESTED[kind](3000))
    out = tmp_path / "f.csv"
    r = invoke(["apply", sample_model, log, "-o", out], code=2)
    assert_one_line_error(r, "log.parquet, column 'tags'", "has no CSV text", "Parquet output")
    assert not out.exists()


@pytest.mark.parametrize("kind", ["list", "struct"])
@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_a_nested_voltage_column_is_refused(tmp_path, sample_model, kind, suffix):
    arr = {"list": pa.array([[0.01]] * 3000), "struct": pa.array([{"v": 0.01}] * 3000)}[kind]
    log, _ = _parquet(tmp_path / "log.parquet", ux=arr)
    out = tmp_path / f"f{suffix}"
    r = invoke(["apply", sample_model, log, "-o", out], code=2)
    assert_one_line_error(r, "log.parquet, column 'ux'", "expected numbers")
    assert not out.exists()


def test_binary_that_is_not_utf8_is_refused_for_csv_and_kept_for_parquet(tmp_path, sample_model):
    cells = [b"ok"] * 3000
    cells[2500] = b"caf\xe9"
    log, _ = _parquet(tmp_path / "log.parquet", raw=pa.array(cells, pa.binary()))
    r = invoke(["apply", sample_model, log, "-o", tmp_path / "f.csv"], code=2)
    assert_one_line_error(r, "row 2502, column 'raw'", "not UTF-8")
    invoke(["apply", sample_model, log, "-o", tmp_path / "f.parquet"])
    assert pq.read_table(tmp_path / "f.parquet").column("raw").to_pylist()[2500] == b"caf\xe9"


@pytest.fixture(scope="module")
def sample_model_obj(sample_model):
    from fsdecouple import load_model

    return load_model(sample_model)  # the suite's sample fit


@pytest.mark.parametrize(("body", "said"), [
    (b'note,b,c\n"x,y",\xe9,z', "row 2, column 'b': '\\xe9'"),  # a quoted separator
    (b'a,note,c\n"he said ""hi""",\xe9t\xe9,z', "row 2, column 'note': '\\xe9t\\xe9'"),
    (b"a\tb\tc\n1\t2\t\xe9", "row 2, column 'c': '\\xe9'"),  # tab-separated, at the end
    (b"t,ux,temp \xb0C," + b"x" * 200_000 + b"\n1,2", "row 1, column 'temp \\xb0C'"),  # a huge field
])
def test_the_cell_of_a_byte_that_is_not_utf8_is_found_by_its_bytes(body, said):
    """A quoted field's separators shifted the cell named; a tab file named the whole line;
    a field beyond csv's size limit raised a traceback instead of the message."""
    from fsdecouple.files.inputs import non_utf8_cell

    assert non_utf8_cell(body).startswith(said)


def test_a_log_block_names_its_cell_by_the_same_rule(tmp_path):
    """A log's blocks (Parquet output) found the cell with csv.reader, a twin of the
    calibration reader's rule: a field beyond csv's 128 KiB limit named no column and
    quoted the whole line."""
    from fsdecouple.data.csv_text import require_utf8

    body = b"1," + b"y" * 200_000 + b",\xe9t\xe9\n2,3,4\n"
    with pytest.raises(InputError) as err:
        require_utf8(body, tmp_path / "log.csv", 40, ["t", "long", "note"], ",", "why")
    assert str(err.value).startswith(f"{tmp_path / 'log.csv'}, row 40, column 'note': "
                                     "'\\xe9t\\xe9' is not UTF-8 text; why")


def test_a_non_utf8_byte_deep_in_a_calibration_file_is_named_too(tmp_path):
    """Bytes past the header's first chunk were refused by pandas as 'not a UTF-8 text
    file', naming no row or column."""
    def edit(lines):
        lines[1:] = [line + b"," + b"y" * 300 if line else line for line in lines[1:]]
        lines[70] = lines[70][:-3] + b"\xe9t\xe9"

    cal = _sample_with_a_note(tmp_path, edit)
    r = invoke(["fit", cal, "-o", tmp_path / "m.json"], code=2)
    assert_one_line_error(r, "rep3.csv, row 71, column 'note': '...", "y\\xe9t\\xe9' is not UTF-8")
