"""The README stays a short front page over the docs site, and the site's pages exist.

The manual lives in docs/ (an mkdocs-material site, ``mkdocs.yml``); CI builds it with
``mkdocs build --strict``, which fails on a broken link inside it.  These tests check
what that build does not see: the README itself, and the blocks the scripts rewrite.
"""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys

import pytest
import yaml
from conftest import ROOT

README = ROOT / "README.md"
MAX_README_LINES = 400
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


def _section(text: str, title: str) -> str:
    m = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", text, re.M | re.S)
    assert m, f"README has no '## {title}' section"
    return m.group(1)


def test_readme_is_short():
    n = len(README.read_text(encoding="utf-8").splitlines())
    assert n <= MAX_README_LINES, f"README.md has {n} lines; move the manual into docs/"


def test_quick_start_has_exactly_two_bash_commands():
    quick = _section(README.read_text(encoding="utf-8"), "Quick start")
    blocks = re.findall(r"^```bash\n(.*?)^```$", quick, re.M | re.S)
    assert len(blocks) == 2, blocks
    assert all(len(b.strip().splitlines()) == 1 for b in blocks), "one command per block"
    install_and_run, tests = (b.strip() for b in blocks)
    assert " fit sample_data/calibration " in install_and_run
    assert tests.endswith("-m pytest")
    assert "sample data" in quick.lower()  # the data are described where they are first used


def test_relative_links_in_the_readme_exist():
    links = [t for t in LINK.findall(README.read_text(encoding="utf-8"))
             if not re.match(r"[a-z]+:", t) and not t.startswith("#")]
    assert links, "the README links into docs/"
    missing = [t for t in links if not (ROOT / t.split("#")[0]).exists()]
    assert not missing, missing
    assert any(t.startswith("docs/") and t.endswith(".md") for t in links)


def _nav_pages(nav) -> list[str]:
    if isinstance(nav, str):
        return [nav]
    if isinstance(nav, list):
        return [p for item in nav for p in _nav_pages(item)]
    if isinstance(nav, dict):
        return [p for v in nav.values() for p in _nav_pages(v)]
    return []


def test_every_page_in_the_nav_exists():
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))
    pages = [p for p in _nav_pages(config["nav"]) if not re.match(r"[a-z]+://", p)]
    assert "index.md" in pages and "api.md" in pages
    missing = [p for p in pages if not (ROOT / config.get("docs_dir", "docs") / p).is_file()]
    assert not missing, missing
    assert len(pages) == len(set(pages)), "a page listed twice"


def test_every_generated_block_has_its_markers_on_its_page():
    sys.path.insert(0, str(ROOT / "docs"))
    try:
        from readme_blocks import PAGES
    finally:
        sys.path.remove(str(ROOT / "docs"))
    for name, page in PAGES.items():
        text = page.read_text(encoding="utf-8")
        assert text.count(f"<!-- {name}:start -->") == 1 == text.count(f"<!-- {name}:end -->"), (name, page)
    readme = README.read_text(encoding="utf-8")
    assert not re.search(r"<!-- [\w-]+:start -->", readme), "generated blocks live in docs/, not the README"


@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("mkdocs") is None, reason="mkdocs is not installed ('.[docs]')")
def test_the_site_builds_strictly(tmp_path):
    run = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path)],
                         cwd=ROOT, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr[-3000:]
    assert (tmp_path / "api" / "index.html").is_file()
