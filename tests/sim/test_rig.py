"""``simulate --rig lever-arm`` and the rig file end to end: init, fit, apply (issue 22)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from conftest import invoke

from fsdecouple.sim.rig import COMPONENTS, FULL_SCALE, LEVELS, rig_rows


def _zero_corrected_log(tmp_path, r):
    """The rig's readings less each sweep's zero row, as a log of the components' names."""
    zero = np.repeat(r[:: LEVELS + 1], LEVELS + 1, axis=0)
    log = tmp_path / "log.csv"
    with log.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(COMPONENTS)
        w.writerows([repr(float(v)) for v in row] for row in r - zero)
    return log

def test_the_rig_file_has_lever_arm_sweeps_after_zero_rows_and_trailing_empty_rows(tmp_path):
    invoke(["simulate", str(tmp_path), "--rig", "lever-arm", "--seed", "4"])
    with (tmp_path / "calibration.csv").open(newline="") as fh:
        rows = list(csv.reader(fh))
    header = rows[0]
    assert header[0] == "timestamp" and "known_Fx" in header and "Known_Mz" in header
    assert header[1:7] == list(COMPONENTS)
    assert rows[-1] == [""] * len(header)  # trailing empty rows, as spreadsheets leave
    f, _ = rig_rows(4)
    assert len(f) == len(COMPONENTS) * (LEVELS + 1)
    assert not f[:: LEVELS + 1].any()  # one zero row before each sweep
    mx = f[:, 3] != 0
    np.testing.assert_allclose(f[mx, 1], -f[mx, 3] / 0.1)  # the lever arm's force


@pytest.mark.slow  # over ~0.6 s: the not-slow run stays under a minute
def test_init_fit_and_apply_on_a_rig_file(tmp_path):
    """init guesses known_* as the loads and Fx..Mz as the readings; fit takes the rows that
    load two components; apply writes force columns apart from the log's own Fx..Mz."""
    invoke(["simulate", str(tmp_path), "--rig", "lever-arm"])
    cal, cfg, model = tmp_path / "calibration.csv", tmp_path / "cfg.yaml", tmp_path / "m.json"
    invoke(["init", str(cal), "-o", str(cfg)])
    invoke(["fit", str(cal), "-c", str(cfg), "-o", str(model), "--no-verdict"])
    f, r = rig_rows(0)
    log = _zero_corrected_log(tmp_path, r)
    out = tmp_path / "forces.csv"
    doc = json.loads(invoke(["apply", str(model), str(log), "-o", str(out), "--json",
                             "--round-trip"]).stdout)
    names = [f"decoupled_{c.lower()}" for c in COMPONENTS]
    assert doc["force_columns"] == names
    with out.open(newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == [*COMPONENTS, *names, "status"]
    got = np.array([[float(x) for x in row[6:12]] for row in rows[1:]])
    # the model decouples its own calibration rows within a few noise sigmas of F.S.
    assert (np.abs(got - f) / FULL_SCALE).max() < 0.005


@pytest.mark.slow  # over ~0.8 s: the not-slow run stays under a minute
def test_validate_scores_a_rig_file_with_its_lever_arm_rows(tmp_path):
    """validate labels a lever-arm row by its moment, as fit does: every component keeps a
    sweep (by raw magnitude the Mx rows' 50 N would outweigh their 5 N·m)."""
    invoke(["simulate", str(tmp_path), "--rig", "lever-arm", "--seed", "1"])
    cal, cfg, model = tmp_path / "calibration.csv", tmp_path / "cfg.yaml", tmp_path / "m.json"
    invoke(["init", str(cal), "-o", str(cfg)])
    invoke(["fit", str(cal), "-c", str(cfg), "-o", str(model), "--no-verdict"])
    doc = json.loads(invoke(["validate", str(model), str(cal), "-c", str(cfg), "--json"]).stdout)
    assert {r["axis"] for r in doc["records"]} == {"fx", "fy", "fz", "mx", "my", "mz"}
    assert any("27 combined-load points" in w for w in doc["warnings"])


def test_the_quadratic_rig_bends_with_its_own_and_the_other_loads(tmp_path):
    """simulate --rig quadratic, the stand-in for issue 22's public rig file: the same
    headers and sweeps; each reading bends with its own load's square by 1-3 % F.S."""
    from fsdecouple.sim.rig import readings, rig_sensor

    invoke(["simulate", str(tmp_path), "--rig", "quadratic", "--seed", "3"])
    with (tmp_path / "calibration.csv").open(newline="") as fh:
        rows = [r for r in csv.reader(fh) if any(r)]
    assert rows[0][1:7] == list(COMPONENTS) and "Known_Mz" in rows[0]
    f, r = rig_rows(3, kind="quadratic")
    assert len(rows) == 1 + len(f)
    sensor = rig_sensor(3, "quadratic")
    own = np.abs(np.diag(sensor["quad"]))
    assert ((own >= 0.01) & (own <= 0.03)).all()
    # at full scale alone the reading is off its straight line by the own square
    s = np.eye(6)
    bend = readings(s, sensor) - readings(s / 2, sensor) * 2  # linear parts cancel
    np.testing.assert_allclose(np.diag(bend), np.diag(sensor["quad"]) / 2
                               + 3 * np.diag(sensor["cubic"]) / 4, rtol=1e-12)


def test_an_unknown_rig_is_refused_in_one_line(tmp_path):
    res = invoke(["simulate", str(tmp_path), "--rig", "lever"], code=2)
    assert "--rig 'lever': expected lever-arm, quadratic or poses" in res.stderr
    assert not (tmp_path / "calibration.csv").exists()


def test_a_rig_is_six_axis_so_components_3_is_refused_and_6_accepted(tmp_path):
    """Issue 34: --components 3 wrote a six-axis rig in silence, while 6 was refused."""
    res = invoke(["simulate", str(tmp_path / "three"), "--rig", "lever-arm", "--components", "3"],
                 code=2)
    assert "--components" in res.stderr and "six components" in res.stderr
    assert not (tmp_path / "three").exists()
    invoke(["simulate", str(tmp_path / "six"), "--rig", "lever-arm", "--components", "6"])
    header = (tmp_path / "six" / "calibration.csv").read_text().splitlines()[0]
    assert header.lower().count("known_") == 6  # Fx .. Mz, as without --components


@pytest.mark.slow  # over ~1 s: two fits
def test_the_cli_fits_applies_and_exports_a_model_with_own_load_chi(tmp_path):
    invoke(["simulate", str(tmp_path), "--rig", "quadratic", "--seed", "2"])
    cal, cfg, model = tmp_path / "calibration.csv", tmp_path / "cfg.yaml", tmp_path / "m.json"
    invoke(["init", str(cal), "-o", str(cfg)])
    invoke(["fit", str(cal), "-c", str(cfg), "-o", str(model), "--no-verdict"])
    doc = json.loads(model.read_text())
    assert doc["format_version"] == 4 and len(doc["chi_own"]) == 6
    f, r = rig_rows(2, kind="quadratic")
    log = _zero_corrected_log(tmp_path, r)
    out = tmp_path / "forces.csv"
    invoke(["apply", str(model), str(log), "-o", str(out)])
    with out.open(newline="") as fh:
        got = np.array([[float(x) for x in row[6:12]] for row in list(csv.reader(fh))[1:]])
    # its own calibration rows within a few noise sigmas (0.1 % F.S.), bends and all
    assert (np.abs(got - f) / FULL_SCALE).max() < 0.006
    # apply took the table path, own-load tables included (tests/core/test_own_tables.py)
    from fsdecouple.core.modelfile import load_model

    assert load_model(model).fast_decoupler() is not None
    invoke(["export", str(model), "-o", str(tmp_path / "d.h")])
    assert "own-load chi_aa(u_a)" in (tmp_path / "d.h").read_text()


def test_a_rig_write_that_fails_leaves_no_directory(tmp_path, monkeypatch):
    """write_rig made its directory before anything could fail, and left it behind."""
    import errno

    from fsdecouple.files import outputs

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(outputs, "place", full)
    res = invoke(["simulate", str(tmp_path / "new" / "rig"), "--rig", "lever-arm"], code=2)
    assert "No space left" in res.stderr
    assert list(tmp_path.iterdir()) == []
