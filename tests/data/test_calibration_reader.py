"""The calibration reader (data/calibration_csv.py, data/csv_text.read_cells) against
independent readings: the csv module for the committed sets, and pandas.read_csv, the
reader it replaces on plain files, for the cells of tricky text."""

from __future__ import annotations

import csv
import io
import random
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import ROOT, SAMPLE

from fsdecouple.config import Settings, load_config
from fsdecouple.data.calibration_csv import read_calibration_table
from fsdecouple.data.csv_text import _split_plain, read_cells, read_csv_text, to_numbers

SETS = [
    (SAMPLE / "calibration", None),
    (SAMPLE / "six_axis" / "calibration", ROOT / "configs" / "six-axis.yaml"),
    # a lab's spreadsheet: a side table with a quoted cell, rows blank in every mapped column
    (SAMPLE / "loadcell" / "calibration.csv", ROOT / "configs" / "loadcell.yaml"),
]


def csv_module_reading(path: Path, settings: Settings) -> pd.DataFrame:
    """The table as docs/data.md describes it, read line by line with the csv module: one
    repetition per file in name order, rows numbered as an editor numbers them, rows blank
    in every mapped column left out, numbers by float() times the config's scale."""
    layout, cols = settings.layout, settings.columns
    numeric = [*layout.loads, *layout.outputs]
    files = sorted(path.glob("*.csv")) if path.is_dir() else [path]
    out = []
    for rep, f in enumerate(files, start=1):
        with open(f, newline="", encoding="utf-8-sig") as fh:
            lines = list(csv.reader(fh, skipinitialspace=True))
        header = [h.strip() for h in lines[0]]
        labelled = cols["axis"] in header
        wanted = [*(["axis"] if labelled else []), *numeric]
        for line, cells in enumerate(lines[1:], start=2):
            cell = {c: cells[header.index(cols[c])].strip() for c in wanted}
            if not any(cell.values()):
                continue
            out.append({"repetition": rep,
                        "axis": layout.label_map()[cell["axis"].lower()] if labelled else "",
                        "file": str(f), "row": line,
                        **{c: float(cell[c]) * settings.scale[c] for c in numeric}})
    return pd.DataFrame(out)


@pytest.mark.parametrize(("path", "config"), SETS, ids=["sample", "six-axis", "loadcell"])
def test_the_table_is_the_files_read_line_by_line(path, config):
    settings = load_config(config)
    table = read_calibration_table(path, settings).table
    want = csv_module_reading(path, settings)
    assert len(want) > 10  # the comparison below has rows to compare
    # same columns in the same order, dtypes (int64 numbers, str labels), rows and values
    # to the last bit: the cells are short decimals, which float() and pandas both round
    # correctly
    pd.testing.assert_frame_equal(table, want, check_exact=True)
    assert list(table.dtypes.astype(str)) == ["int64", "str", "str", "int64",
                                              *["float64"] * (len(table.columns) - 4)]


PLAIN = [  # read by read_cells' own split: (text, width)
    ("a,b,c\n1,2,3\n4,5,6\n", 3),
    ("a,b,c\r\n1,2,3\r\n4,5,6", 3),  # Windows line ends, no end on the last line
    ("a,b,c\n 1,  2 ,3\n", 3),  # spaces after a separator skipped, trailing ones kept
    ('a,b,c\n1,"2,5",3\n', 3),  # a separator inside a quoted value
    ('a,b,c\n1, " 2 ","x""y"\n', 3),  # spaces inside quotes kept, a doubled quote
    ("a,b,c\n1,2,3\n\n4,5,6\n\n\n", 3),  # blank lines: rows of empty cells
    ("a,b,c\n1,2,3\n   \n\t,x\n", 3),  # white space only; a tab is not skipped
    ("a,b,c\n1\n1,2\n", 3),  # short rows padded with empty cells
    ("\ufeffa;b\n1,5;2\n", 2),  # a byte-order mark, a ';' file
    ("a,b\nÿ,\u00a0x\n", 2),  # non-ASCII text
    ("a,b\n", 2),  # header only
]
LEFT_TO_PANDAS = [
    ("a,b,c\n1,2,3\r4,5,6\n", 3),  # a line ending in \r alone
    ('a,b,c\n1,2"x,3\n', 3),  # a quote inside an unquoted value
    ('a,b,c\n1,"2" ,3\n', 3),  # text after a closing quote
    ('a,b,c\n1,"2\n5",3\n', 3),  # a value over two lines
    ('"a",b,c\n1,2,3\n', 3),  # a quoted header
]


def pandas_cells(text: str, width: int, settings: Settings) -> list:
    raw = read_csv_text(io.BytesIO(text.encode()), settings, path=Path("x.csv"), header=0,
                        names=[str(i) for i in range(width)])
    return raw.to_numpy(dtype=object).reshape(len(raw), width).tolist()


def settings_for(text: str) -> Settings:
    return replace(Settings(), sep=";", decimal=",") if ";" in text else Settings()


@pytest.mark.parametrize(("text", "width"), PLAIN)
def test_plain_text_is_split_as_pandas_reads_it(text, width):
    settings = settings_for(text)
    split = _split_plain(text.encode(), settings.sep, width)
    assert split is not None  # the fast path, not pandas, read it
    cells, spaced = split
    assert cells.tolist() == pandas_cells(text, width, settings)
    assert spaced or all(c == c.strip() for c in cells.ravel())


@pytest.mark.parametrize(("text", "width"), LEFT_TO_PANDAS)
def test_other_text_is_left_to_pandas(text, width):
    settings = settings_for(text)
    assert _split_plain(text.encode(), settings.sep, width) is None
    cells, _ = read_cells(text.encode(), settings, Path("x.csv"), width)
    assert cells.tolist() == pandas_cells(text, width, settings)


def test_random_text_is_read_as_pandas_reads_it():
    """Lines of random fields (quoted or not, spaces, blanks, too few or too many): wherever
    the split reads a text itself, its cells are pandas'."""
    rng = random.Random(0)
    tokens = ["", " ", "1.5", " 1.5", "1.5 ", '"1,5"', ' "q"', '""', '"a""b"', '" x "', "\t1",
              "é", "\u00a0", "nan", '"', 'x"y', '"x"y', '"a\nb"', "\ufeffz"]
    settings = Settings()
    split = 0
    for _ in range(200):
        width = rng.randrange(1, 5)
        lines = [",".join(f"c{i}" for i in range(width))]
        for _ in range(rng.randrange(0, 5)):
            n = rng.randrange(0, width + 1 + (rng.random() < 0.1))
            lines.append(",".join(rng.choice(tokens) for _ in range(n)))
        nl = rng.choice(["\n", "\r\n"])
        text = nl.join(lines) + rng.choice(["", nl, nl * 2])
        got = _split_plain(text.encode(), ",", width)
        if got is None:
            continue
        split += 1
        assert got[0].tolist() == pandas_cells(text, width, settings), repr(text)
    assert split > 60  # most texts took the split (the rest: pandas' refusals, odd quotes)


def test_the_cells_are_strings_in_an_object_array():
    cells, _ = read_cells(b"a,b\n1,2\n", Settings(), Path("x.csv"), 2)
    assert cells.dtype == object and cells.shape == (1, 2)
    assert np.array_equal(cells, np.array([["1", "2"]], dtype=object))


def test_numbers_are_pandas_to_numeric_of_the_whole_column():
    """to_numbers parses each distinct cell once and gives it back to every row holding it:
    bit for bit pandas' reading of the whole column (which reads a column of whole numbers
    as integers, then converts), on columns mixing kinds, repeats and digits past a
    double's."""
    rng = random.Random(1)
    kinds = ["0", "522", "-1", "+7", "007", "1.5", "-0.0", "1e5", ".5", "3.336568",
             "9007199254740993", "18446744073709551617", "-9223372036854775809",
             "123456789012345678901234567890", "0.1234567890123456789",
             "1.00000000000000011102230246251565"]
    for _ in range(300):
        pool = rng.sample(kinds, rng.randrange(1, 5))
        cells = np.array([rng.choice(pool) for _ in range(rng.randrange(1, 40))], dtype=object)
        got = to_numbers(cells, Path("x.csv"), "ux", 2, stripped=True)
        want = pd.to_numeric(pd.Series(cells, dtype="str")).to_numpy(dtype=float)
        assert np.array_equal(got.view(np.uint64), want.view(np.uint64)), cells.tolist()
