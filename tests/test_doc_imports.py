"""Every ``from fsdecouple... import ...`` in the README, docs/ (scripts and pages) and benchmarks/ resolves.

Those files are run by hand, so nothing else notices when a module they import is
renamed.  Each import line is its own case; the ones broken today are strict xfails
naming the rename, so fixing them turns the marker into a failure to remove.
"""

from __future__ import annotations

import importlib
import re

import pytest
from conftest import ROOT

IMPORT = re.compile(r"^\s*(?:>>> )?from (fsdecouple(?:\.[a-z_.]+)?) import ([A-Za-z_, ]+)", re.M)
SOURCES = ["README.md", *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.py")),
           *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").rglob("*.md")),
           *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "benchmarks").glob("*.py"))]
# (source, module) -> reason, for an import known to be broken (a strict xfail)
BROKEN: dict[tuple[str, str], str] = {}


def cases():
    out = []
    for src in SOURCES:
        for m in IMPORT.finditer((ROOT / src).read_text(encoding="utf-8")):
            module, names = m.group(1), [n.strip() for n in m.group(2).split(",") if n.strip()]
            reason = BROKEN.get((src, module))
            marks = [pytest.mark.xfail(strict=True, raises=ImportError, reason=reason)] if reason else []
            out.append(pytest.param(module, names, id=f"{src}:{module}", marks=marks))
    return out


@pytest.mark.parametrize("module, names", cases())
def test_documented_import_resolves(module, names):
    mod = importlib.import_module(module)
    missing = [n for n in names if not hasattr(mod, n)]
    if missing:
        raise ImportError(f"cannot import {', '.join(missing)} from {module}")


def test_every_source_has_been_scanned():
    scanned = {c.id.split(":")[0] for c in cases()}  # the sources with at least one import
    # the docs pages (the API page and the Dask example), a docs script and the benchmarks
    assert {"docs/api.md", "docs/apply.md", "docs/make_figures.py", "benchmarks/accuracy.py"} <= scanned
    assert sum(s.startswith("docs/design/") for s in SOURCES) >= 1  # the design notes too
    assert len(cases()) >= 8  # docs pages (2), docs scripts (1), benchmarks (5) today
