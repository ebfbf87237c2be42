"""fit-many's command: what it prints of each sensor, beside its table."""

from __future__ import annotations

from conftest import invoke

from fsdecouple.fleet import sensors
from fsdecouple.fleet.sensors import FleetResult, SensorResult


def test_fit_many_prints_each_sensors_warnings_named_by_the_sensor(tmp_path, monkeypatch):
    """The table counted a sensor's warnings ('6') and printed none of them: a CSV fitted
    as a repetition with loads beyond full scale passed with exit 0 and no word."""
    said = ["validation.csv: 12 loads beyond the full scale", "one repetition per sweep"]
    ok = SensorResult("s1", "d/s1", model="m/s1.json", k={"x": 0.01}, units={"load": "gf", "output":
                      "count", "k": {"x": "count/gf"}}, method="svr", worst_gamma=0.001,
                      better="svr", warnings=said)

    def fit_many(sensors_dir, output, **_):
        return FleetResult(str(sensors_dir), str(output), [ok])

    monkeypatch.setattr(sensors, "fit_many", fit_many)
    r = invoke(["fit-many", tmp_path, "-o", tmp_path / "models"])
    assert [line for line in r.stderr.splitlines() if line.startswith("warning:")] == [
        f"warning: s1: {w}" for w in said]
    r = invoke(["fit-many", tmp_path, "-o", tmp_path / "models", "--json"])
    assert "warning: s1: one repetition per sweep" in r.stderr
