"""Rig files as labs type them (issue 32 item 5): a blank load cell skips its row with a
warning naming the line (``--strict`` refuses it), and ``--exclude FILE:LINE`` drops any
line, even one that cannot be parsed; lines as an editor numbers them, header = 1."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import assert_one_line_error, invoke

from fsdecouple.config import load_config
from fsdecouple.data.calibration import load_calibration
from fsdecouple.data.init_config import init_config
from fsdecouple.sim.rig import write_rig


def rig(tmp_path: Path, line: int, column: str, value: str) -> tuple[Path, Path]:
    """The lever-arm rig with one cell of ``line`` (editor numbering) replaced."""
    path = write_rig(tmp_path / "rig", seed=0)[0]
    init_config(path, tmp_path / "cfg.yaml")
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    cells = lines[line - 1].split(",")
    cells[header.index(column)] = value
    lines[line - 1] = ",".join(cells)
    edited = tmp_path / "edited.csv"
    edited.write_text("\n".join(lines) + "\n")
    return edited, tmp_path / "cfg.yaml"


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_a_blank_load_cell_skips_its_line_with_a_warning(tmp_path):
    path, cfg = rig(tmp_path, 61, "Known_Mx", "")
    whole = load_calibration(path.parent / "rig" / "calibration.csv", load_config(cfg))
    calib = load_calibration(path, load_config(cfg))
    assert 61 not in set(calib.points["row"]) and len(calib.points) == len(whole.points) - 1
    assert any("line 61" in w and "'Known_Mx'" in w and "blank" in w for w in calib.warnings)
    r = invoke(["fit", path, "-c", cfg, "-o", tmp_path / "m.json", "--no-verdict"])
    assert "line 61" in r.stderr


def test_strict_refuses_a_blank_load_cell(tmp_path):
    path, cfg = rig(tmp_path, 61, "Known_Mx", "")
    r = invoke(["fit", path, "-c", cfg, "-o", tmp_path / "m.json", "--strict"], code=2)
    assert_one_line_error(r, "row 61", "Known_Mx", "--strict")
    assert not (tmp_path / "m.json").exists()


def test_exclude_drops_a_line_that_cannot_be_parsed(tmp_path):
    path, cfg = rig(tmp_path, 30, "Fz", "n/a")
    r = invoke(["fit", path, "-c", cfg, "-o", tmp_path / "m.json"], code=2)
    assert_one_line_error(r, "row 30", "'Fz'")
    invoke(["fit", path, "-c", cfg, "-o", tmp_path / "m.json", "--no-verdict", "--exclude",
            f"{path.name}:30"])
    calib = load_calibration(path, load_config(cfg), exclude=[f"{path.name}:30"])
    assert 30 not in set(calib.points["row"])
    assert any("row 30: excluded as asked" in s for s in calib.excluded)


def test_exclude_names_the_same_line_a_message_names(tmp_path):
    # a blank row's skip warning and --exclude count alike: line 61 is the 60th data row
    path, cfg = rig(tmp_path, 61, "Known_Mx", "")
    calib = load_calibration(path, load_config(cfg), exclude=[f"{path.name}:61", f"{path.name}:5"])
    rows = set(calib.points["row"])
    assert 5 not in rows and 4 in rows and 6 in rows
    assert not any("blank" in w for w in calib.warnings)  # line 61 never read


def test_exclude_of_a_line_beyond_the_file_is_refused(tmp_path):
    path, cfg = rig(tmp_path, 61, "Known_Mx", "")
    r = invoke(["fit", path, "-c", cfg, "-o", tmp_path / "m.json", "--exclude",
                f"{path.name}:9999"], code=2)
    assert_one_line_error(r, "line 9999", "not a data line")
    r = invoke(["fit", path, "-c", cfg, "-o", tmp_path / "m.json", "--exclude",
                f"{path.name}:1"], code=2)
    assert_one_line_error(r, "header")
