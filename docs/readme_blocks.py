"""Replace a generated block of a docs page between two HTML comment markers.

Used by the scripts that write measured or printed output into the docs and the
README (docs/make_readme_output.py, benchmarks/*.py --docs), so that no figure in them
is typed in by hand.  Each block lives on one page of the docs site; ``PAGES``
says which, so a script names its block and nothing else.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
# block name -> the page holding its <!-- NAME:start --> ... <!-- NAME:end --> markers
PAGES = {
    "benchmarks": DOCS / "benchmarks.md",           # benchmarks/run.py --docs
    "refine-benchmarks": DOCS / "benchmarks.md",    # benchmarks/refine.py --docs
    "accuracy": DOCS / "benchmarks.md",             # benchmarks/accuracy.py --docs
    "accuracy-six": DOCS / "benchmarks.md",         # benchmarks/accuracy.py --six --docs
    "fleet-benchmarks": DOCS / "benchmarks.md",     # benchmarks/fleet.py --docs
    "six-axis-benchmarks": DOCS / "benchmarks.md",  # benchmarks/six_axis.py --docs
}


if str(DOCS) not in sys.path:
    sys.path.insert(0, str(DOCS))
from examples import EXAMPLES  # noqa: E402

# docs/make_readme_output.py: the example outputs (README.md's among them)
PAGES.update({e.name: ROOT / e.page for e in EXAMPLES})


def page_of(name: str) -> Path:
    """The page that holds block ``name``."""
    try:
        return PAGES[name]
    except KeyError:
        raise SystemExit(f"no docs page holds a block named {name!r}; known: {', '.join(PAGES)}") from None


def replace_block(name: str, text: str, page: Path | None = None) -> Path:
    """Put ``text`` between ``<!-- NAME:start -->`` and ``<!-- NAME:end -->`` on the block's
    page (``PAGES``, or ``page`` if given); returns the page written."""
    page = Path(page) if page is not None else page_of(name)
    start, end = f"<!-- {name}:start -->", f"<!-- {name}:end -->"
    body = page.read_text(encoding="utf-8")
    new, n = re.subn(re.escape(start) + r".*?" + re.escape(end),
                     lambda _: f"{start}\n{text.rstrip()}\n{end}", body, flags=re.S)
    if n != 1:
        raise SystemExit(f"{page}: expected one {start} ... {end} block, found {n}")
    page.write_text(new, encoding="utf-8")
    return page


def written(page: Path, name: str) -> str:
    """The line a script prints after rewriting a block."""
    try:
        shown = page.resolve().relative_to(ROOT)
    except ValueError:
        shown = page
    return f"{shown}: {name} block rewritten"
