"""Write the digest-valid but inconsistent model files of tests/data/bad/.

Each case is the golden version-2 model with one value changed and its digest
recomputed by :func:`fsdecouple.modelfile.content_digest` (never by hand):
``python tests/data/make_bad_models.py``.
"""

from __future__ import annotations

import json
from pathlib import Path

from fsdecouple.modelfile import content_digest

HERE = Path(__file__).parent
BASE = HERE / "golden" / "model-v2.json"


def huge_slope(doc):  # k = 1e300: every force of eq. (11) is nan
    doc["omega"]["y"]["k"] = 1e300


def table_disagrees(doc):  # the fast path's table 1 mV off its own kernel sum
    s = doc["chi"]["xy"]["surrogate"]
    s["values"] = [v + 1e-3 for v in s["values"]]


def negative_input_scale(doc):
    doc["chi"]["zx"]["input_scale"] = -1.0


def inverted_input_range(doc):
    lo, hi = doc["chi"]["yz"]["input_range"]
    doc["chi"]["yz"]["input_range"] = [hi, lo]


CASES = {
    "model-huge-slope": huge_slope,
    "model-table-disagrees": table_disagrees,
    "model-negative-input-scale": negative_input_scale,
    "model-inverted-input-range": inverted_input_range,
}


def main() -> None:
    for name, change in CASES.items():
        doc = json.loads(BASE.read_text(encoding="utf-8"))
        change(doc)
        doc["integrity"]["digest"] = content_digest(doc)
        out = HERE / "bad" / name / "model.json"
        out.parent.mkdir(exist_ok=True)
        out.write_text(json.dumps(doc, indent=1, sort_keys=True, allow_nan=False) + "\n",
                       encoding="utf-8")


if __name__ == "__main__":
    main()
