"""init on a rig's headers (issue 22): applied loads by prefix or suffix in any case, with
or without a unit, the readings named like the components, a timestamp ignored."""

from __future__ import annotations

import csv
import json

import pytest
from conftest import invoke

from fsdecouple.sim.rig import write_rig

HEADER = ["Time (s)", "Fx [N]", "Fy [N]", "Fz [N]", "Mx [Nm]", "My [Nm]", "Mz [Nm]",
          "applied_fx", "Fy_ref", "known_Fz [N]", "Known_Mx", "My_true", "REF_Mz"]


@pytest.mark.slow  # over ~0.8 s of CPU: the not-slow run stays under a minute
def test_init_maps_applied_loads_and_readings_whatever_their_spelling(tmp_path):
    path = write_rig(tmp_path, seed=2)[0]
    with path.open(newline="") as fh:
        rows = list(csv.reader(fh))
    rows[0] = HEADER
    with path.open("w", newline="") as fh:
        csv.writer(fh).writerows(rows)
    doc = json.loads(invoke(["init", path, "-o", tmp_path / "c.yaml", "--json"]).stdout)
    comps = ["fx", "fy", "fz", "mx", "my", "mz"]
    assert doc["components"] == comps
    assert [doc["columns"][c] for c in comps] == HEADER[7:]
    assert [doc["columns"][o] for o in doc["outputs"]] == HEADER[1:7]
    assert doc["ignored_columns"] == [{"column": 1, "name": "Time (s)",
                                       "reason": "a timestamp: not used"}]
    # and the config it wrote is one fit accepts
    invoke(["fit", path, "-c", tmp_path / "c.yaml", "-o", tmp_path / "m.json", "--no-verdict"])
