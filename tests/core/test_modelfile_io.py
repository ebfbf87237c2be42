"""The model file read and written cheaply: the same bytes as json's own writer, the same
digest, and the same refusals as a parse that checks every float on its own.

The references are json itself (``json.dumps(indent=1, sort_keys=True)`` for the file,
the canonical dump for the digest) and, for where a bad value is, the test's own
knowledge of what it put where.
"""

from __future__ import annotations

import json
import re
import shutil

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fsdecouple.core.modelfile import content_digest, load_model, model_to_dict, save_model
from fsdecouple.core.modeljson import dump_forms, join_indented
from fsdecouple.errors import ModelFileError

FLOAT = re.compile(r"-?\d+\.\d+(?:e-?\d+)?")


def json_text(doc) -> str:
    """What the model file was always: json's indented, sorted dump and a newline."""
    return json.dumps(doc, indent=1, sort_keys=True, allow_nan=False) + "\n"


@pytest.fixture(scope="module")
def saved(tmp_path_factory, model):
    """The session's fitted model, saved: (path, its text)."""
    path = tmp_path_factory.mktemp("modelio") / "m.json"
    save_model(model, path)
    return path, path.read_text(encoding="utf-8")


def test_saved_bytes_are_jsons_and_the_digest_content_digest(saved, model):
    path, text = saved
    doc = model_to_dict(model)
    assert text == json_text(doc)
    assert json.loads(text)["integrity"]["digest"] == content_digest(doc)


@pytest.mark.slow  # fits the rig and six-axis models when no earlier test has (2 s)
def test_saved_bytes_of_own_chi_and_six_axis_models(tmp_path, rig_model, six_model_file):
    """A joint fit's chi_own and tables, and a six-axis fit with its verdict and certificate:
    the keys and arrays a three-axis model has none of."""
    six = load_model(six_model_file)
    for m in (rig_model, six):
        path = tmp_path / "m.json"
        save_model(m, path)
        assert path.read_text(encoding="utf-8") == json_text(model_to_dict(m))
    # a load and a save give back the file fit wrote, byte for byte
    assert path.read_bytes() == six_model_file.read_bytes()


scalars = st.one_of(
    st.none(), st.booleans(), st.integers(min_value=-(10**40), max_value=10**40),
    st.floats(allow_nan=False, allow_infinity=False), st.text(max_size=8),
)
# lists of numbers only (json's C encoder writes them), with a bool now and then (not a number)
number_lists = st.lists(st.one_of(st.floats(allow_nan=False, allow_infinity=False),
                                  st.integers(), st.booleans()),
                        max_size=6)
values = st.recursive(
    scalars | number_lists,
    lambda inner: st.lists(inner, max_size=4) | st.tuples(inner, inner)
    | st.dictionaries(st.text(max_size=6), inner, max_size=4),
    max_leaves=20,
)
documents = st.dictionaries(
    st.sampled_from(["chi", "created", "integrity", "omega", "r\u00e9port", "a\"b\\c", "k\n"])
    | st.text(max_size=5), values, max_size=6)


@pytest.mark.slow  # a property test: 1 s of CPU
@settings(max_examples=100, deadline=None)
@given(documents)
def test_both_forms_are_jsons_own(doc):
    canonical, indented = dump_forms(doc, leave_out=("integrity", "created"))
    body = {k: v for k, v in doc.items() if k not in ("integrity", "created")}
    assert canonical == json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False)
    assert join_indented(indented) == json.dumps(doc, indent=1, sort_keys=True, allow_nan=False)


@pytest.mark.parametrize("doc", [
    {"a": np.float64(0.1), "b": [np.float64(1e-300), 2.5], "c": (1, 2.0)},  # float subclass
    {"a": {1: 2.0, 3: [1.0]}},  # int keys: json writes them as strings
    {"a": [1.0, {"b": []}, {}, [[]]]},
])
def test_what_the_fast_path_leaves_to_json_is_written_as_json_writes_it(doc):
    canonical, indented = dump_forms(doc, leave_out=())
    assert canonical == json.dumps(doc, sort_keys=True, separators=(",", ":"), allow_nan=False)
    assert join_indented(indented) == json.dumps(doc, indent=1, sort_keys=True, allow_nan=False)


@pytest.mark.parametrize("doc, error", [
    ({"a": [1.0, float("nan")]}, ValueError),
    ({"a": {"b": float("inf")}}, ValueError),
    ({"a": [1.0, "x", -float("inf")]}, ValueError),
    ({"a": object()}, TypeError),
    ({"a": [np.int64(1)]}, TypeError),
])
def test_a_document_json_refuses_is_refused(doc, error):
    with pytest.raises(error):
        json.dumps(doc, allow_nan=False)
    with pytest.raises(error):
        dump_forms(doc, leave_out=())


def _replace(text: str, edits: dict[int, str]) -> str:
    """``text`` with its i-th float literal replaced by ``edits[i]``."""
    spans = list(FLOAT.finditer(text))
    for i in sorted(edits, reverse=True):
        m = spans[i]
        text = text[:m.start()] + edits[i] + text[m.end():]
    return text


@pytest.mark.parametrize("first, later", [
    ("1e999", "NaN"), ("NaN", "1e999"), ("-1e999", "Infinity"), ("-Infinity", "1e999"),
])
def test_the_first_non_finite_value_is_the_one_named(tmp_path, saved, first, later):
    _, text = saved
    n = len(FLOAT.findall(text))
    for i, j in ((3, n // 2), (n // 3, n - 2)):
        path = tmp_path / "m.json"
        path.write_text(_replace(text, {i: first, j: later}), encoding="utf-8")
        with pytest.raises(ModelFileError, match=re.escape(f"holds '{first}'; NaN and infinity")):
            load_model(path)


def test_a_non_finite_value_before_a_syntax_error_is_named_and_after_it_is_not(tmp_path, saved):
    _, text = saved
    path = tmp_path / "m.json"
    path.write_text(_replace(text, {5: "1e999"})[:-40], encoding="utf-8")  # truncated after
    with pytest.raises(ModelFileError, match="holds '1e999'"):
        load_model(path)
    # a stray brace early, the infinity later: the parse stops at the brace
    spans = list(FLOAT.finditer(text))
    edited = _replace(text, {len(spans) - 3: "1e999"})
    at = spans[5].start()
    path.write_text(edited[:at] + "}" + edited[at:], encoding="utf-8")
    row, col = text.count("\n", 0, at) + 1, at - text.rfind("\n", 0, at)
    with pytest.raises(ModelFileError, match=f"row {row}, column {col}: not valid JSON"):
        load_model(path)


def test_a_duplicate_key_and_an_infinity_the_first_is_named(tmp_path, saved):
    _, text = saved
    dup = text.replace('"rho": ', '"rho": 0.5, "rho": ', 1)
    n, rho = len(FLOAT.findall(dup)), dup.index('"rho": 0.5')
    path = tmp_path / "m.json"
    path.write_text(_replace(dup, {n - 2: "1e999"}), encoding="utf-8")  # the infinity after
    with pytest.raises(ModelFileError, match="key 'rho' appears twice"):
        load_model(path)
    assert FLOAT.search(dup).start() < rho  # the first float comes before the second rho
    path.write_text(_replace(dup, {0: "1e999"}), encoding="utf-8")
    with pytest.raises(ModelFileError, match="holds '1e999'"):
        load_model(path)


@pytest.mark.parametrize("edit", [
    lambda t: re.sub(r'"created": "[^"]*"', '"created": 1e999', t, count=1),  # not digested
    lambda t: t.replace('"integrity": {', '"integrity": {"x": -1e999, ', 1),
    lambda t: "[1.0, 1e999]",  # not a model at all: the number is still what is wrong
])
def test_a_non_finite_value_outside_the_digest_is_refused(tmp_path, saved, edit):
    _, text = saved
    path = tmp_path / "m.json"
    path.write_text(edit(text), encoding="utf-8")
    with pytest.raises(ModelFileError, match="e999'; NaN and infinity are not allowed"):
        load_model(path)


def test_an_edited_number_is_refused_by_the_digest(tmp_path, saved):
    """The digest load computes is over the file's content, not a copy of the stored one."""
    _, text = saved
    m = list(FLOAT.finditer(text))[len(FLOAT.findall(text)) // 2]
    last = m.group()[-1]
    edited = text[:m.end() - 1] + ("1" if last != "1" else "2") + text[m.end():]
    path = tmp_path / "m.json"
    path.write_text(edited, encoding="utf-8")
    with pytest.raises(ModelFileError, match="integrity check failed"):
        load_model(path)


@pytest.mark.parametrize("layout", ["compact", "crlf", "reversed keys"])
def test_the_same_content_written_otherwise_loads_and_decouples_alike(tmp_path, saved, layout):
    """The digest covers the parsed content, so another writer's layout of it still loads."""
    path, text = saved
    doc = json.loads(text)
    other = {"compact": lambda: json.dumps(doc, separators=(",", ":")),
             "crlf": lambda: text.replace("\n", "\r\n"),
             "reversed keys": lambda: json.dumps(dict(reversed(list(doc.items()))), indent=3),
             }[layout]()
    copy = tmp_path / "m.json"
    copy.write_text(other, encoding="utf-8", newline="")
    u = np.random.default_rng(0).uniform(-0.05, 0.05, (50, 3))
    np.testing.assert_array_equal(load_model(copy).decouple(u), load_model(path).decouple(u))


def test_a_bom_is_not_content(tmp_path, saved):
    path, _ = saved
    copy = tmp_path / "m.json"
    shutil.copy(path, copy)
    copy.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    assert model_to_dict(load_model(copy)) == model_to_dict(load_model(path))


@pytest.mark.parametrize("where, value, loads", [
    ("outputs", True, False),  # a bool is no number
    ("outputs", "1.0", False),
    ("outputs", None, False),
    ("U", True, False),
    ("load", [1.0], False),
    ("outputs", np.float64(0.25), True),  # a float subclass, as a document built in memory holds
    ("outputs", 3, True),  # an int is a number
])
def test_a_certificates_numbers_are_numbers(six_model_file, where, value, loads):
    """The certificate's lists are checked item by item: one wrong item in the ~10^4 of a
    six-axis certificate is refused, with a valid digest; a number of another type is not."""
    from fsdecouple.core.modelfile import model_from_dict

    doc = json.loads(six_model_file.read_text(encoding="utf-8"))
    steps = doc["report"]["certificate"]["steps"]
    axis = sorted(steps)[-1]
    row = steps[axis][where][-1] if where == "outputs" else steps[axis][where]
    row[-1] = value
    doc["integrity"]["digest"] = content_digest(doc)
    if loads:
        assert model_from_dict(doc).report.certificate["steps"][axis][where][-1][-1] == value
    else:
        with pytest.raises(ModelFileError, match="certificate needs steps and interval scores"):
            model_from_dict(doc)


@pytest.mark.parametrize("provenance, named", [
    ([1, 2], "provenance"),
    ({"files": "rep1.csv"}, "provenance.files"),
    ({"files": [{"path": 1, "sha256": "ab"}]}, "provenance.files"),
    ({"libraries": ["numpy"]}, "provenance.libraries"),
    ({"excluded": [3]}, "provenance.excluded"),
])
def test_a_provenance_not_as_fit_writes_it_is_refused(saved, provenance, named):
    """A list in its place, with a recomputed digest, gave tracebacks in show, apply and report."""
    from fsdecouple.core.modelfile import model_from_dict

    doc = json.loads(saved[1])
    doc["provenance"] = provenance
    doc["integrity"]["digest"] = content_digest(doc)
    with pytest.raises(ModelFileError, match=re.escape(f"({named} is not as fit writes it)")):
        model_from_dict(doc)
