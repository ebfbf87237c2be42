"""Write the golden model file of the current format version (never edit it by hand).

    PYTHONPATH=. python tests/data/make_golden.py [--force]

Fits ``sample_data/calibration`` with the built-in settings and writes
``tests/data/golden/model-v<FORMAT_VERSION>.json``, and fits ``sample_data/six_axis``
with ``configs/six-axis.yaml`` into ``six-axis-v<FORMAT_VERSION>.json`` (from version
3, which reads N-component sensors).  Files of older versions are
kept as they are, so tests/test_golden.py proves old model files still load.
Run from the repository root: the provenance records the relative input paths,
and ``created`` is fixed, so regenerating on another machine changes only the
library versions in the provenance.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from fsdecouple import FsdecoupleError, load_calibration, load_config
from fsdecouple.modelfile import FORMAT_VERSION, save_model
from fsdecouple.verdict import calibrate

ROOT = Path(__file__).resolve().parents[2]
CREATED = "2026-01-01T00:00:00+00:00"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--force", action="store_true", help="replace this version's file")
    args = parser.parse_args()
    os.chdir(ROOT)
    settings = load_config()
    # as `fsdecouple fit` makes it: the model and its held-out verdict (format 2)
    model = calibrate(load_calibration(Path("sample_data/calibration"), settings), settings,
                      workers=1)
    six_settings = load_config(Path("configs/six-axis.yaml"))
    six = calibrate(load_calibration(Path("sample_data/six_axis/calibration"), six_settings),
                    six_settings, workers=1)
    for m, name in ((model, "model"), (six, "six-axis")):
        m.created = CREATED
        out = Path("tests/data/golden") / f"{name}-v{FORMAT_VERSION}.json"
        try:
            save_model(m, out, force=args.force)
        except FsdecoupleError as err:
            raise SystemExit(f"error: {err}") from None
        print(f"wrote {out}")


if __name__ == "__main__":
    main()
