"""Regenerate every example output quoted in README.md and the docs pages.

    python docs/make_readme_output.py            # run every example, rewrite its block
    python docs/make_readme_output.py readme-fit # only the blocks named
    python docs/make_readme_output.py --check    # rewrite nothing; exit 1 if a block is stale

Each example of docs/examples.py runs its commands for real (``python -m fsdecouple``
from this checkout, in a scratch directory holding links to ``sample_data/`` and ``configs/``) and
its block, between ``<!-- NAME:start -->`` and ``<!-- NAME:end -->`` on its page,
is replaced by what they printed.  Never edit those blocks by hand: change the code,
then run this script (tests/test_docs.py fails when a block is stale).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "docs"))
from examples import EXAMPLES, Result, block, masked, run  # noqa: E402
from readme_blocks import replace_block, written  # noqa: E402

# Output that is not a terminal is never wrapped (fsdecouple.cli.app.WIDE); colour off.
ENV = {**os.environ, "NO_COLOR": "1", "TERM": "dumb", "PYTHONPATH": str(ROOT), "CI": "true"}


def subprocess_runner(argv) -> Result:
    run_ = subprocess.run([sys.executable, "-m", "fsdecouple", *argv], env=ENV,
                          capture_output=True, text=True, encoding="utf-8")
    return Result(run_.returncode, run_.stdout, run_.stderr)


@contextlib.contextmanager
def scratch(tmp: Path, group: str):
    """The group's scratch directory, as the current directory."""
    d = tmp / group
    if not d.exists():
        d.mkdir()
        for name in ("sample_data", "configs"):
            (d / name).symlink_to(ROOT / name, target_is_directory=True)
    here = Path.cwd()
    os.chdir(d)
    try:
        yield d
    finally:
        os.chdir(here)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help="only these blocks (default: all)")
    parser.add_argument("--check", action="store_true", help="compare, rewrite nothing")
    args = parser.parse_args(argv)
    unknown = set(args.names) - {e.name for e in EXAMPLES}
    if unknown:
        parser.error(f"no example named {', '.join(sorted(unknown))}")
    # a group runs whole (apply needs fit's model) but only the named blocks are written
    groups = {e.group for e in EXAMPLES if not args.names or e.name in args.names}
    stale = []
    done: dict[str, dict] = {g: {} for g in groups}  # per group: the commands run, their results
    with tempfile.TemporaryDirectory() as tmp:
        for example in EXAMPLES:
            if example.group not in groups:
                continue
            with scratch(Path(tmp), example.group):
                text = run(example, subprocess_runner, done[example.group])
            if args.names and example.name not in args.names:
                continue
            if masked(text, example.volatile) != masked(block(example), example.volatile):
                stale.append(example.name)
            if not args.check:
                print(written(replace_block(example.name, text, ROOT / example.page), example.name))
    if args.check and stale:
        print("stale: " + ", ".join(stale) + " (run python docs/make_readme_output.py)")
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
