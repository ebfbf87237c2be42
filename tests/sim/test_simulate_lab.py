"""`fsdecouple simulate --layout lab`: a load cell in a lab's spreadsheet (sample_data/loadcell).

Today's calibration reader refuses the empty headers of this layout, so these tests
read the files with the csv module and check their content against the simulator's
known truth; reading them with `ingest` belongs to the reader's tests.
"""

from __future__ import annotations

import csv

import numpy as np
import pytest
import yaml
from conftest import ROOT, SAMPLE, invoke

from fsdecouple.axes import AXES
from fsdecouple.config import settings_from_dict
from fsdecouple.sim.simulate import (
    LOAD_CELL_FULL_SCALE,
    LOAD_CELL_SLOPES,
    load_cell_sensor,
    simulate,
)

LAB = SAMPLE / "loadcell"
N = len(AXES)
ADC_LIMIT = 2**23  # a signed 24-bit ADC reads -2^23 .. 2^23 - 1


def read_lab(path):
    """(header, data rows as (loads, counts), side-table rows, side rows below the data)."""
    with open(path, newline="", encoding="utf-8") as fh:
        header, *rows = list(csv.reader(fh))
    width = 2 * N
    data = [r for r in rows if any(r[:width])]
    below = rows[len(data):]
    assert all(not any(r[:width]) for r in below), "data rows must come first, without gaps"
    loads = np.array([[float(v) for v in r[:N]] for r in data])
    counts = [r[N:width] for r in data]
    side = [r[width + 2:] for r in rows if any(r[width + 2:])]
    return header, loads, counts, side, below


def sweeps(loads):
    """Row indices of each sweep: a zero row starts one (no axis column)."""
    starts = [i for i, f in enumerate(loads) if not f.any()]
    return [list(range(a, b)) for a, b in zip(starts, [*starts[1:], len(loads)], strict=True)]


@pytest.mark.parametrize("name", ["calibration.csv", "validation.csv"])
def test_layout_is_a_lab_spreadsheet(name):
    header, loads, counts, side, below = read_lab(LAB / name)
    assert header == ["Fx [gf]", "Fy [gf]", "Fz [gf]", "ch0", "ch1", "ch2", "", "",
                      "orientation", "load on x", "load on y", "load on z"]
    # the side table runs past the data, and there every data cell is empty
    assert len(below) >= 2 and all(r[8] for r in below)
    assert any(not _is_number(v) for r in side for v in r[1:] if v)  # text among the numbers
    # counts are whole numbers a 24-bit ADC can read
    for row in counts:
        for v in row:
            assert v.lstrip("-").isdigit(), v
            assert -ADC_LIMIT <= int(v) < ADC_LIMIT
    # one repetition: each axis one sweep, a zero row then four loads, increasing
    groups = sweeps(loads)
    assert len(groups) == N
    for a, rows in enumerate(groups):
        f = loads[rows]
        assert len(rows) == 5 and not f[0].any()
        assert (np.delete(f, a, axis=1) == 0).all() and (np.diff(f[:, a]) > 0).all()


def _is_number(text):
    try:
        float(text)
    except ValueError:
        return False
    return True


def test_calibration_and_validation_loads():
    _, cal, *_ = read_lab(LAB / "calibration.csv")
    _, val, *_ = read_lab(LAB / "validation.csv")
    fs = np.array(LOAD_CELL_FULL_SCALE)
    for a in range(N):
        cal_loads = np.unique(cal[:, a][cal[:, a] > 0])
        val_loads = np.unique(val[:, a][val[:, a] > 0])
        assert cal_loads.tolist() == [250, 500, 750, 1000] and cal_loads.max() == fs[a]
        # weights only: never a negative load
        assert (cal >= 0).all() and (val >= 0).all()
        # validation: other loads, and beyond the calibrated range
        assert val_loads.tolist() == [300, 600, 900, 1200]
        assert not set(cal_loads) & set(val_loads) and val_loads.max() > fs[a]


def zero_corrected(path):
    """Loads and counts minus each sweep's zero row, read from the file."""
    _, loads, counts, *_ = read_lab(path)
    u = np.array([[float(v) for v in r] for r in counts])
    for rows in sweeps(loads):
        u[rows] -= u[rows[0]]
    return loads, u


@pytest.mark.parametrize("name", ["calibration.csv", "validation.csv"])
def test_files_hold_the_simulated_load_cell(name):
    """Zero-corrected counts are the true sensor's outputs plus noise, in both files."""
    sensor = load_cell_sensor()
    loads, u = zero_corrected(LAB / name)
    # each value is a reading minus the sweep's zero reading: noise sd 25 counts
    # twice, sqrt(2) * 25 = 35 counts, plus half a count of rounding each; 6 sd
    # over 45 values is never reached by chance
    bound = 6 * np.sqrt(2) * sensor.noise + 1
    assert np.abs(u - sensor.voltages(loads)).max() < bound
    # the slopes, by least squares through the origin on each prime channel
    for a in range(N):
        rows = loads[:, a] > 0
        k = (loads[rows, a] @ u[rows, a]) / (loads[rows, a] @ loads[rows, a])
        # slope error ~ noise / sqrt(sum f^2) ~ 35 / 1400 = 0.03 counts/gf, and
        # the coupling does not enter the prime channel (eq. 1)
        assert k == pytest.approx(LOAD_CELL_SLOPES[a], abs=0.2)


def test_coupling_is_a_few_percent_of_full_scale_output():
    """Per pair, the largest coupled output is 0.5-3 % of the full-scale output."""
    loads, u = zero_corrected(LAB / "calibration.csv")
    full_out = np.abs(np.array(LOAD_CELL_SLOPES) * np.array(LOAD_CELL_FULL_SCALE))
    for b in range(N):
        rows = loads[:, b] > 0
        for a in range(N):
            if a != b:
                # noise (<= 6 * 35 counts) is below 0.03 % of the smallest full-scale output
                assert 0.004 < np.abs(u[rows, a]).max() / full_out[a] < 0.032, (a, b)
    # nonlinear: the coupled output is not proportional to the load
    x = loads[:, 0] > 0
    ratio = u[x, 2] / loads[x, 0]
    assert np.ptp(ratio) > 5 * 6 * np.sqrt(2) * 25 / 250


def test_offsets_differ_between_sweeps_and_files():
    _, cal, cal_counts, *_ = read_lab(LAB / "calibration.csv")
    _, val, val_counts, *_ = read_lab(LAB / "validation.csv")
    zeros = np.array([[int(v) for v in c[i]] for c, f in ((cal_counts, cal), (val_counts, val))
                      for i in range(len(f)) if not f[i].any()])
    assert len(zeros) == 2 * N
    assert ((np.abs(zeros) > 0.9e5) & (np.abs(zeros) < 1.1e6)).all()
    assert len(np.unique(zeros, axis=0)) == len(zeros)


def test_true_parameters_are_not_in_the_files():
    """The side table holds loads and notes, never a slope or the noise."""
    secrets = {f"{abs(k):g}" for k in LOAD_CELL_SLOPES} | {"counts/gf", "noise", "sensitivity"}
    for name in ("calibration.csv", "validation.csv"):
        _, loads, _, side, _ = read_lab(LAB / name)
        text = (LAB / name).read_text()
        assert not any(s in text for s in secrets), name
        numbers = {float(v) for r in side for v in r[1:] if v and _is_number(v)}
        assert numbers <= set(loads.ravel()), name


def test_sample_loadcell_is_the_simulator_output(tmp_path):
    """sample_data/loadcell/ is exactly what `simulate --layout lab --seed 0` writes."""
    r = invoke(["simulate", tmp_path, "--layout", "lab", "--seed", "0"])
    assert "wrote 2 files" in r.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["calibration.csv", "validation.csv"]
    for name in ("calibration.csv", "validation.csv"):
        assert (tmp_path / name).read_bytes() == (LAB / name).read_bytes(), name


def test_other_seeds_give_other_noise_same_sensor(tmp_path):
    simulate(tmp_path, layout="lab", seed=5)
    assert (tmp_path / "calibration.csv").read_bytes() != (LAB / "calibration.csv").read_bytes()
    loads, u = zero_corrected(tmp_path / "calibration.csv")
    assert np.abs(u - load_cell_sensor().voltages(loads)).max() < 6 * np.sqrt(2) * 25 + 1


def test_levels_and_repetitions(tmp_path):
    invoke(["simulate", tmp_path, "--layout", "lab", "--levels", "3", "--repetitions", "2"])
    with open(tmp_path / "calibration.csv", newline="") as fh:
        header, *rows = list(csv.reader(fh))
    # more than one repetition: a repetition column, so a reader can tell them apart
    assert header[0] == "repetition" and header[1:7] == ["Fx [gf]", "Fy [gf]", "Fz [gf]",
                                                         "ch0", "ch1", "ch2"]
    data = [r for r in rows if r[0]]
    assert [r[0] for r in data] == ["1"] * 12 + ["2"] * 12
    fx = [r[1] for r in data[:4]]
    assert fx == ["0", "333.333", "666.667", "1000"]  # rounded loads are the true loads


def test_paper_layout_repetitions(tmp_path):
    invoke(["simulate", tmp_path, "--repetitions", "2"])
    assert sorted(p.name for p in (tmp_path / "calibration").iterdir()) == ["rep1.csv", "rep2.csv"]
    # the same seed gives the same first repetitions as the six-repetition sample
    assert (tmp_path / "calibration" / "rep1.csv").read_bytes() == (
        SAMPLE / "calibration" / "rep1.csv").read_bytes()


def test_gross_error_moves_one_lab_point(tmp_path):
    simulate(tmp_path, layout="lab", seed=0, gross_error=_gross("y:1:3:5000"))
    _, _, moved, *_ = read_lab(tmp_path / "calibration.csv")
    _, _, clean, *_ = read_lab(LAB / "calibration.csv")
    diff = np.array(moved, dtype=int) - np.array(clean, dtype=int)
    # point 3 of the y sweep is data row 5 + 3; its prime output is ch1
    assert diff[7, 1] == 5000 and np.count_nonzero(diff) == 1


def _gross(spec):
    from fsdecouple.data.calibration import GrossError

    return GrossError.parse(spec)


@pytest.mark.parametrize(("args", "message"), [
    (["--layout", "lab", "--levels", "0"], "--levels 0: expected a whole number >= 1"),
    (["--layout", "lab", "--repetitions", "0"], "--repetitions 0: expected a whole number >= 1"),
    (["--repetitions", "0"], "--repetitions 0: expected a whole number >= 1"),
    (["--layout", "lab", "--seed", "-1"], "--seed -1: expected a whole number >= 0"),
    (["--seed", "-1"], "--seed -1: expected a whole number >= 0"),
    (["--layout", "spreadsheet"], "--layout 'spreadsheet': expected one of paper, lab"),
    (["--levels", "4"], "--levels: only with --layout lab"),
    (["--layout", "lab", "--gross-error", "x:1:9:100"], "has 5 points, no point 9"),
    # the offset was blamed on REP and POINT, and a missing repetition read as 0 points
    (["--gross-error", "x:1:5:nan"], "'x:1:5:nan': OFFSET 'nan' is not a finite number"),
    (["--gross-error", "x:9:5:0.2"], "the x sweep has no repetition 9 (repetitions: 1, 2, 3"),
])
def test_bad_options_exit_2_and_write_nothing(tmp_path, args, message):
    out = tmp_path / "out"
    r = invoke(["simulate", out, *args], code=2)
    assert message in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_lab_outputs_are_all_or_nothing(tmp_path):
    (tmp_path / "validation.csv").write_text("precious")
    r = invoke(["simulate", tmp_path, "--layout", "lab"], code=2)
    assert "validation.csv" in r.stderr and "--force" in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["validation.csv"]
    assert (tmp_path / "validation.csv").read_text() == "precious"
    invoke(["simulate", tmp_path, "--layout", "lab", "--force"])
    assert (tmp_path / "validation.csv").read_bytes() == (LAB / "validation.csv").read_bytes()


def test_config_describes_the_sample_file():
    raw = yaml.safe_load((ROOT / "configs" / "loadcell.yaml").read_text())
    assert set(raw) == {"sensor", "columns", "units", "full_scale", "min_repetitions", "scaling"}
    assert raw["units"] == {"load": "gf", "output": "count"}
    with open(LAB / "calibration.csv", newline="") as fh:
        header = next(csv.reader(fh))
    assert [raw["columns"][c] for c in ("fx", "fy", "fz", "ux", "uy", "uz")] == header[:6]
    _, loads, *_ = read_lab(LAB / "calibration.csv")
    assert [raw["full_scale"][a] for a in AXES] == loads.max(axis=0).tolist()
    # everything but `units` (not yet known to this parser) is a valid config today
    settings = settings_from_dict({k: v for k, v in raw.items() if k != "units"})
    assert settings.min_repetitions == 1 and settings.scaling == "full_scale"
    assert settings.full_scale == LOAD_CELL_FULL_SCALE
