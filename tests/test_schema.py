"""The config's keys, declared once (fsdecouple/schema.py, issue 30).

Every key the docs name and every shipped config uses is in the schema; every schema
key has a default and a doc line; validation refuses an unknown key with a hint and a
malformed value by its key, and tells the keys written from the defaults.
"""

from __future__ import annotations

import re

import pytest
import yaml
from conftest import ROOT

from fsdecouple.config import Settings, settings_from_dict
from fsdecouple.errors import ConfigError
from fsdecouple.schema import APPLY_KEYS, KEYS, SCHEMA


def test_every_key_is_declared_once_with_a_default_and_a_doc():
    assert len(KEYS) == len(SCHEMA)
    for key in SCHEMA:
        assert key.default and key.doc, key.name


def test_the_shipped_configs_and_the_docs_name_only_schema_keys():
    for path in (ROOT / "configs").glob("*.yaml"):
        assert set(yaml.safe_load(path.read_text())) <= set(KEYS), path.name
    docs = (ROOT / "docs" / "data.md").read_text()
    section = docs.split("## Configuration keys", 1)[1].split("\n## ", 1)[0]
    named = set(re.findall(r"`([a-z_0-9]+)[.`]", section.split("Unknown keys")[0]))
    # every top-level key is documented there, and every key named there exists
    top = {k.name for k in SCHEMA} - {"serial", "reference", "reference_uncertainty",
                                      "environment", "creep", "drift"}  # docs/certificate.md
    assert top <= named, top - named


@pytest.mark.parametrize("raw, needle", [
    ({"full_scal": {"x": 1}}, "unknown key 'full_scal' (did you mean 'full_scale'?)"),
    ({"svr": {"tolerence": 1e-3}}, "svr: unknown key 'tolerence' (did you mean 'tolerance'?)"),
    ({"min_repetitions": 0}, "min_repetitions: expected a whole number >= 1, found 0"),
    ({"min_repetitions": True}, "min_repetitions: expected a whole number >= 1"),
    ({"refine": 101}, "refine: expected a whole number of refinement steps from 0 to 100"),
    ({"scaling": "volts"}, "scaling: expected one of none, full_scale, found 'volts'"),
    ({"svr": {"C": 1e13}}, "svr: C: expected 1e-12 .. 1e+12"),
    ({"checks": {"min_r2": -1}}, "checks: min_r2: must be greater than 0"),
    ({"csv": {"sep": ".", "decimal": "."}}, "csv: sep and decimal must differ"),
])
def test_malformed_or_unknown_keys_are_refused_by_name(raw, needle):
    with pytest.raises(ConfigError, match=re.escape(f"cfg.yaml: {needle}")):
        settings_from_dict(raw, "cfg.yaml")


def test_the_keys_written_are_told_from_the_defaults():
    s = settings_from_dict({"rotation": None, "svr": {"C": 10}}, "cfg.yaml")
    assert s.given == {"rotation", "svr"} and s.svr.C == 10.0
    assert s == Settings(svr=s.svr)  # what was written, nothing else, changed
    assert "given" not in s.to_dict()  # not a setting: model files keep their bytes
    assert set(APPLY_KEYS) == {"components", "outputs", "columns", "scale", "csv", "limits",
                               "units"}
