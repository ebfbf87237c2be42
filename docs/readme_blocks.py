"""Replace a generated block of README.md between two HTML comment markers.

Used by the scripts that write measured or printed output into the README
(docs/make_readme_output.py, benchmarks/run.py --readme), so that no figure in
it is typed in by hand.
"""

from __future__ import annotations

import re
from pathlib import Path

README = Path(__file__).resolve().parent.parent / "README.md"


def replace_block(name: str, text: str, readme: Path = README) -> None:
    """Put ``text`` between ``<!-- NAME:start -->`` and ``<!-- NAME:end -->``."""
    start, end = f"<!-- {name}:start -->", f"<!-- {name}:end -->"
    body = readme.read_text(encoding="utf-8")
    new, n = re.subn(re.escape(start) + r".*?" + re.escape(end),
                     lambda _: f"{start}\n{text.rstrip()}\n{end}", body, flags=re.S)
    if n != 1:
        raise SystemExit(f"{readme}: expected one {start} ... {end} block, found {n}")
    readme.write_text(new, encoding="utf-8")
