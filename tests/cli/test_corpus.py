"""The malformed-input corpus: every case under tests/fixtures/bad/ is one directory.

``case.yaml`` says what is wrong (``about``), the ``command`` to run and the
substrings the one-line error must contain (``expect``: the file name and, where
it applies, ``row N`` and ``column 'x'``).  Placeholders in the command:

``{case}``   a copy of the case directory;
``{cal}``    a copy of sample_data/calibration with the case's ``cal/`` files laid
             over it (the files listed in ``remove`` deleted, and the ``symlinks``
             (name: target) and ``dirs`` given made);
``{model}``  a good model file fitted on sample_data/calibration;
``{log}``    sample_data/task_voltages.csv;
``{six}``    a copy of sample_data/six_axis/calibration with the case's ``six/`` files
             laid over it (and ``remove`` deleted), read with ``{six_config}``,
             configs/six-axis.yaml; ``{six_model}`` a good model fitted on it;
``{fast_config}`` tests/fixtures/fast-svr.yaml (Table 2's libsvm tolerance), for cases
             whose fit only leads up to the error.

Commands that write (``output``, default true) get ``-o OUT`` appended.  The
contract checked: exit 2, exactly one line on stderr starting ``error:``, no
traceback, and OUT neither created nor, when it existed and ``--force`` was
given, changed; no temporary file left.  ``report`` cases build their figures but do not
rasterise them (conftest's ``unrendered``): the error paths are the point.  A case with
``main: true`` is a usage error (an option's value refused by its parser): it runs as
``python -m fsdecouple`` in a subprocess, through the CLI's main, which makes it one line.
A case with ``exit: 0`` is accepted input that must warn (``warn`` substrings); for
``apply`` it may give the number of output ``rows`` and the ``last_status``.  Add a case by
adding a directory.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pandas as pd
import pytest
import yaml
from conftest import FAST_CONFIG, ROOT, SAMPLE, invoke

BAD = Path(__file__).parents[1] / "fixtures" / "bad"
CASES = sorted(p.name for p in BAD.iterdir() if (p / "case.yaml").is_file())
# Cases whose cost is the work itself, run in the full (CI) run only: each takes 2-5 s
# of the not-slow run's budget, against ~0.1 s for a typical case.
SLOW_CASES = {
    "cfg-deeply-nested",  # the YAML parser's own time on the hostile nesting
    "report-png-under-a-file",  # renders every figure before the PNG write fails
    "out-file-named-as-a-directory",  # a usage error: through the CLI's main, in a subprocess
    "six-model-three-column-log",  # fits a six-axis model (also test_six_axis.py, not slow)
    "cal-huge-off-axis-output",  # fits twice (plain, then --force) before gamma overflows
}


@pytest.fixture(scope="module")
def good_model(sample_model):
    """A good model fitted on sample_data/calibration: conftest's sample_model, fitted once
    a session (the cases only read it)."""
    return sample_model


SIX_CONFIG = ROOT / "configs" / "six-axis.yaml"


def _overlay(src: Path, case: Path, sub: str, spec: dict, dest: Path) -> str:
    shutil.copytree(src, dest)
    if (case / sub).is_dir():
        for f in (case / sub).iterdir():
            shutil.copy(f, dest / f.name)
    for f in spec.get("remove", []):
        (dest / f).unlink()
    return str(dest)


def prepare(name: str, tmp_path: Path, good_model: Path,
            request=None) -> tuple[dict, list[str]]:
    spec = yaml.safe_load((BAD / name / "case.yaml").read_text(encoding="utf-8"))
    case = tmp_path / name
    shutil.copytree(BAD / name, case)
    (case / "case.yaml").unlink()
    values = {"case": str(case), "model": str(good_model), "log": str(SAMPLE / "task_voltages.csv"),
              "six_config": str(SIX_CONFIG), "fast_config": str(FAST_CONFIG)}
    if any("{six}" in a for a in spec["command"]):
        values["six"] = _overlay(SAMPLE / "six_axis" / "calibration", case, "six", spec,
                                 tmp_path / "six")
    if any("{six_model}" in a for a in spec["command"]):
        values["six_model"] = str(request.getfixturevalue("six_model_file"))  # conftest's, once
    if any("{cal}" in a for a in spec["command"]):
        cal = tmp_path / "cal"
        shutil.copytree(SAMPLE / "calibration", cal)
        if (case / "cal").is_dir():
            for f in (case / "cal").iterdir():
                shutil.copy(f, cal / f.name)
        for f in spec.get("remove", []):
            (cal / f).unlink()
        # what git cannot carry: a dangling symbolic link, an empty directory
        for f, target in spec.get("symlinks", {}).items():
            (cal / f).symlink_to(target)
        for f in spec.get("dirs", []):
            (cal / f).mkdir()
        values["cal"] = str(cal)
    return spec, [a.format(**values) for a in spec["command"]]


def test_corpus_is_large_enough():
    refused = [c for c in CASES if yaml.safe_load((BAD / c / "case.yaml").read_text()).get("exit", 2) == 2]
    assert len(refused) >= 40


@pytest.mark.parametrize("name", [pytest.param(c, marks=pytest.mark.slow) if c in SLOW_CASES else c
                                  for c in CASES])
def test_bad_input(name, tmp_path, good_model, request):
    spec, args = prepare(name, tmp_path, good_model, request)
    if args[0] == "report":
        request.getfixturevalue("unrendered")
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    out = out_dir / "result.out"
    writes = spec.get("output", True)
    full = [*args, "-o", out] if writes else args
    if spec.get("exit", 2) == 0:
        r = invoke(full)
        for needle in spec.get("warn", []):
            assert needle in r.stderr, (needle, r.stderr)
        assert "Traceback" not in r.stderr + r.stdout
        if "rows" in spec:  # apply: every input row out, in order, with its status
            # pass-through bytes need not be UTF-8 (docs/errors.md: the encoding rule); latin-1 reads any
            f = pd.read_csv(out, dtype=str, keep_default_na=False, encoding="latin-1")
            assert len(f) == spec["rows"]
            assert f["status"].iat[-1] == spec["last_status"]
        return
    r = _through_main(full) if spec.get("main") else invoke(full, code=2)
    msg = r.stderr.strip()
    assert msg.startswith("error:") and len(msg.splitlines()) == 1, msg
    assert "Traceback" not in r.stderr + r.stdout
    for needle in spec["expect"]:
        assert needle in msg, f"{needle!r} not in: {msg}"
    assert list(out_dir.iterdir()) == []
    if writes and not spec.get("main"):
        # an existing output is left byte for byte as it was, even with --force
        out.write_bytes(b"previous result\n")
        invoke([*full, "--force"], code=2)
        assert out.read_bytes() == b"previous result\n"
        assert [p.name for p in out_dir.iterdir()] == ["result.out"]


def _through_main(args):
    import os
    import subprocess
    import sys
    from types import SimpleNamespace

    p = subprocess.run([sys.executable, "-m", "fsdecouple", *map(str, args)], capture_output=True,
                       text=True, env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120)
    assert p.returncode == 2, (p.returncode, p.stderr)
    return SimpleNamespace(stdout=p.stdout, stderr=p.stderr)
