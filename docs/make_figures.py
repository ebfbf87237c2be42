"""Regenerate the figure of the README and docs/report.md (docs/figure7.png) from the sample data.

Run from the repository root:  python docs/make_figures.py
"""

from __future__ import annotations

from pathlib import Path

import fsdecouple
from fsdecouple.reporting.report import build_report

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    settings = fsdecouple.load_config()
    calib = fsdecouple.load_calibration(ROOT / "sample_data" / "calibration", settings)
    model = fsdecouple.fit(calib, settings)
    report = build_report(model, calib=calib)
    out = ROOT / "docs" / "figure7.png"
    out.write_bytes(report.figures["figure7_chi"])
    print(f"wrote {out.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
