"""init reads units from headers in any common spelling, and a sensor's own readings named
like its components are in load units, not millivolts (issue 25, item 4)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from conftest import SAMPLE, invoke

from fsdecouple.units import LOAD_UNITS, MOMENT_UNITS

SIX = SAMPLE / "six_axis" / "calibration" / "rep1.csv"


def six_axis_file(tmp_path, force_unit: str, moment_unit: str, *, glue=" "):
    """The six-axis sample with its loads headed ``Fx <force_unit>`` .. ``Mz <moment_unit>``."""
    t = pd.read_csv(SIX).drop(columns=["axis"])
    names = {c: f"{c.capitalize()}{glue}{force_unit if c[0] == 'f' else moment_unit}"
             for c in ["fx", "fy", "fz", "mx", "my", "mz"]}
    path = tmp_path / "six.csv"
    t.rename(columns=names).to_csv(path, index=False)
    return path


def init_doc(path, tmp_path):
    return json.loads(invoke(["init", path, "-o", tmp_path / "c.yaml", "--json", "--force"]).stdout)


@pytest.mark.parametrize(("spelled", "glue", "newton_metres"), [
    ("[N·m]", " ", 1.0), ("(N.m)", " ", 1.0), ("[Nm]", " ", 1.0), ("Nm", "_", 1.0),
    ("[Nmm]", " ", 1e-3), ("[N mm]", " ", 1e-3), ("Nmm", "_", 1e-3), ("(N*mm)", " ", 1e-3),
    ("[kgf·cm]", " ", 9.80665e-2), ("[kgf cm]", " ", 9.80665e-2), ("[N·cm]", " ", 1e-2),
])
def test_moment_units_in_any_spelling(tmp_path, spelled, glue, newton_metres):
    path = six_axis_file(tmp_path, "[N]" if glue == " " else "N", spelled, glue=glue)
    doc = init_doc(path, tmp_path)
    units = doc["load_units"]
    assert [units[c] for c in ("fx", "fy", "fz")] == ["N"] * 3
    assert {MOMENT_UNITS[units[c]] for c in ("mx", "my", "mz")} == {newton_metres}
    assert not any("no unit in the headers of" in n or "no known unit" in n for n in doc["notes"])


@pytest.mark.parametrize(("spelled", "unit"), [
    ("[gf]", "gf"), ("(g)", "gf"), ("_gf", "gf"), ("[kgf]", "kgf"), ("(lbf)", "lbf"), ("[kN]", "kN"),
])
def test_force_units_in_any_spelling(tmp_path, spelled, unit):
    glue = "" if spelled.startswith("_") else " "
    path = six_axis_file(tmp_path, spelled, "[N·m]", glue=glue)
    units = init_doc(path, tmp_path)["load_units"]
    assert [units[c] for c in ("fx", "fy", "fz")] == [unit] * 3 and unit in LOAD_UNITS


def test_an_unknown_header_unit_is_named_not_called_missing(tmp_path):
    doc = init_doc(six_axis_file(tmp_path, "[N]", "[furlong]"), tmp_path)
    note = next(n for n in doc["notes"] if "furlong" in n)
    assert "'Mx [furlong]'" in note and "set units:" in note
    assert not any("no unit in the headers of" in n for n in doc["notes"])


def rig(tmp_path, readings, applied, rows=None):
    """A rig file: applied loads and the sensor's own readings (a 2 % cross-talk matrix)."""
    t = pd.read_csv(SIX)
    comps = ["fx", "fy", "fz", "mx", "my", "mz"][:len(readings)]
    f = t[comps].to_numpy()
    m = np.eye(len(comps)) + 0.02 * np.random.default_rng(0).standard_normal((len(comps),) * 2)
    r = f @ m.T + 1e-3 * np.random.default_rng(1).standard_normal(f.shape)
    out = pd.DataFrame({**{a: f[:, k] for k, a in enumerate(applied)},
                        **{n: r[:, k] for k, n in enumerate(readings)}})
    path = tmp_path / "rig.csv"
    out.to_csv(path, index=False)
    return path


@pytest.mark.parametrize("headed", [False, True])
@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_readings_named_like_the_components_are_in_load_units(tmp_path, headed):
    """Readings of 200 (N) were guessed 'mV' from their magnitude."""
    u = (" [N]", " [N·m]") if headed else ("", "")
    readings = [f"{c}{u[c[0] == 'M']}" for c in ["Fx", "Fy", "Fz", "Mx", "My", "Mz"]]
    path = rig(tmp_path, readings, [f"applied_{c}" for c in ["fx", "fy", "fz", "mx", "my", "mz"]])
    doc = init_doc(path, tmp_path)
    assert doc["units"]["output"] == "mixed"
    assert doc["output_units"] == {o: ("N·m" if o[0] == "m" else "N") for o in doc["outputs"]}
    assert "factory-calibrated" in doc["reasons"]["units"]
    assert not any("mV" in n for n in doc["notes"])
    invoke(["fit", path, "-c", tmp_path / "c.yaml", "-o", tmp_path / "m.json", "--no-verdict"])
    shown = invoke(["show", tmp_path / "m.json"]).stdout
    assert "mV" not in shown


def test_a_three_axis_rig_in_gram_force(tmp_path):
    """Fx_ref [gf] beside the readings Fx: the readings are in gram-force too."""
    path = rig(tmp_path, ["Fx", "Fy", "Fz"], ["Fx_ref [gf]", "Fy_ref [gf]", "Fz_ref [gf]"])
    doc = init_doc(path, tmp_path)
    assert doc["units"] == {"load": "gf", "output": "gf"}
    assert [doc["columns"][o] for o in doc["outputs"]] == ["Fx", "Fy", "Fz"]
    invoke(["fit", path, "-c", tmp_path / "c.yaml", "-o", tmp_path / "m.json", "--no-verdict"])
