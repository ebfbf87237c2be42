"""Issue 13, class 6: results that were silently wrong now say what they are."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import assert_one_line_error, invoke

from fsdecouple.core.model import FORCE_LIMIT
from fsdecouple.core.modelfile import load_model
from fsdecouple.logs.apply import RowRules, decouple_rows
from fsdecouple.logs.reader import Block
from fsdecouple.logs.sinks import CsvSink


def test_csv_rounding_never_writes_inf_for_a_finite_force(tmp_path):
    # np.round(-7.5e306, 8) overflows to -inf; the text must stay the finite value
    f = np.array([[-7.5e306, 1.5e300, 0.123456789123]])
    block = Block(2, np.zeros((1, 3)), lines=pa.array([b"1,2,3"], pa.binary()))
    sink = CsvSink(_Sink(), ["ux", "uy", "uz"], b"ux,uy,uz", decimals=8)
    text = b"".join(bytes(p) for p in sink.encode(block, f, np.zeros(1, bool)))
    assert b"inf" not in text
    assert [float(v) for v in text.decode().split(",")[3:6]] == [-7.5e306, 1.5e300, 0.12345679]


class _Sink:
    def write(self, data):
        pass


def test_forces_beyond_the_bound_are_not_finite(sample_model):
    model = load_model(sample_model)
    bound = FORCE_LIMIT * max(model.settings.full_scale)
    # x force about u / k_x: one row just inside the bound, one beyond, one at 1e300
    k = model.k[0]
    raw = np.array([[0.5 * bound * k, 0, 0], [2 * bound * k, 0, 0], [1e300, 0, 0]])
    f, code, empty = decouple_rows(model, raw, np.zeros(3), RowRules.for_model(model))
    assert empty.tolist() == [False, True, True]
    assert np.abs(f[0]).max() <= bound


def test_inf_voltage_is_one_rule_in_csv_and_parquet(sample_model, tmp_path):
    pd.DataFrame({"ux": ["0.01", "0.02"], "uy": ["0.0", "inf"], "uz": ["0.0", "0.0"]}) \
        .to_csv(tmp_path / "log.csv", index=False)
    pq.write_table(pa.table({"ux": [0.01, 0.02], "uy": [0.0, np.inf], "uz": [0.0, 0.0]}),
                   tmp_path / "log.parquet")
    for name in ("log.csv", "log.parquet"):
        r = invoke(["apply", sample_model, tmp_path / name, "-o", tmp_path / f"out-{name}"], code=2)
        assert_one_line_error(r, name, "row 3", "column 'uy'", "expected a finite number")
        assert not (tmp_path / f"out-{name}").exists()


@pytest.mark.parametrize("csv, key", [("{decimal: e}", "decimal"), ("{decimal: ';'}", "decimal"),
                                      ("{sep: '1'}", "sep"), ("{sep: '-'}", "sep"),
                                      ("{sep: '\"'}", "sep")])
def test_a_csv_dialect_that_misreads_numbers_is_refused(tmp_path, csv, key):
    """decimal 'e' was accepted, and apply wrote 1.08651756 as '1e08651756'."""
    from fsdecouple.config import load_config
    from fsdecouple.errors import ConfigError

    cfg = tmp_path / "c.yaml"
    cfg.write_text(f"csv: {csv}\n")
    with pytest.raises(ConfigError, match=f"csv: {key}: expected"):
        load_config(cfg)
    cfg.write_text("csv: {sep: ';', decimal: ','}\n")
    s = load_config(cfg)
    assert (s.sep, s.decimal) == (";", ",")  # the European dialect still reads
