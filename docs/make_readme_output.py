"""Regenerate the sample `fsdecouple cv` output quoted in the docs (docs/cv.md).

Runs the command below on the committed sample data, writes its printed text to
docs/cv-sample-output.txt and copies that text into docs/cv.md between the
``<!-- cv-sample-output:start -->`` and ``<!-- cv-sample-output:end -->`` markers.
Never edit either by hand; run ``python docs/make_readme_output.py`` from the
repository root instead.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "docs"))
from readme_blocks import replace_block  # noqa: E402

ARGS = [
    "cv", "sample_data/calibration",
    "--task", "sample_data/task_voltages.csv", "--task-forces", "sample_data/task_forces.csv",
    "--task-tare", "200", "--gross-error", "x:1:5:0.2", "--max-gamma", "0.016",
]
WIDTH = 132


def main() -> int:
    env = {**os.environ, "COLUMNS": str(WIDTH), "NO_COLOR": "1", "TERM": "dumb",
           "PYTHONPATH": str(ROOT)}
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "fsdecouple", *ARGS, "-o", str(Path(tmp) / "cv.json")]
        run = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
    if run.returncode not in (0, 1):
        sys.stderr.write(run.stderr)
        return run.returncode
    lines = [line.rstrip() for line in run.stdout.splitlines()]
    lines = [line for line in lines if not line.startswith("cv document written to")]
    text = "$ fsdecouple " + " ".join(ARGS) + " -o cv.json\n" + "\n".join(lines).rstrip() + "\n"
    (ROOT / "docs" / "cv-sample-output.txt").write_text(text, encoding="utf-8")
    page = replace_block("cv-sample-output", f"```text\n{text}```")
    print(f"wrote docs/cv-sample-output.txt and {page.relative_to(ROOT)} ({len(lines)} lines)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
