"""The cv.json document of ``fsdecouple cv``: its format, how to read it, its vocabulary.

:func:`fsdecouple.evaluation.cv.run_cv` writes it; the console tables and the HTML report
read it through the helpers here, so both name the test sets alike and index
the records the same way.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from ..errors import InputError, excerpt, printable, where
from ..files.inputs import CV_LIMIT, read_bounded
from ..files.outputs import atomic_write

FORMAT = "fsdecouple.cv"
# cv --refine K: the rounds' svr models decoupled with K refinement steps (eqs. 5-6), a
# method row of its own beside the svr row (whose K is the config's); nothing is trained
REFINED = "svr-refined"
FORMAT_VERSION = 1
TEST_NAMES = ("I", "II", "III", "IV")  # Section 4.1: "test data I" and "test data II"


def test_name(i: int) -> str:
    """The paper's name of the i-th (0-based) held-out set of a round."""
    return TEST_NAMES[i] if i < len(TEST_NAMES) else str(i + 1)


def scored_axes(doc: dict[str, Any], records=None) -> list[str]:
    """The components a cv document's records score, in the sensor's order (its settings'
    full_scale): under the levels protocol the first round may hold out only the sweep with
    the most levels (z), whose column then came first."""
    from ..axes import labels_in

    axes = labels_in(doc.get("records") if records is None else records)
    order = list((doc.get("settings") or {}).get("full_scale") or {})
    return sorted(axes, key=lambda a: order.index(a) if a in order else len(order))


def gamma_index(records) -> dict[tuple, float]:
    """(round, test_set, method, axis) -> gamma of eq. (12), from cv.json records."""
    return {(r["round"], r["test_set"], r["method"], r["axis"]): r["value"]
            for r in records or [] if r.get("metric", "gamma") == "gamma"}


def cv_text(doc: dict[str, Any]) -> str:
    """The cv.json text of a document (what ``cv -o`` writes and ``cv --json`` prints)."""
    return json.dumps(doc, indent=1, sort_keys=True, allow_nan=False) + "\n"


def save_cv_results(doc: dict[str, Any], path: str | Path, *, force: bool = False) -> None:
    """Write a cv.json document, atomically (never half a file)."""
    with atomic_write(Path(path), force=force) as fh:
        fh.write(cv_text(doc))


def load_cv_results(path: str | Path) -> dict[str, Any]:
    """Read a cv.json document written by ``fsdecouple cv``."""
    path = Path(path)
    try:
        doc = json.loads(read_bounded(path, CV_LIMIT, "cv results").decode("utf-8"))
    except FileNotFoundError:
        raise InputError(f"{printable(path)}: cv results not found") from None
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(f"{printable(path)}: cannot read cv results ({err})") from None
    except json.JSONDecodeError as err:
        raise InputError(f"{where(path, err.lineno)}: not valid JSON (truncated?)") from None
    except RecursionError:
        raise InputError(f"{printable(path)}: not a cv.json (JSON too deeply nested)") from None
    except ValueError as err:  # e.g. an integer of more than 4300 digits
        raise InputError(f"{printable(path)}: not a cv.json ({excerpt(err)})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise InputError(f"{path}: not a cv.json of fsdecouple cv (format is not '{FORMAT}')")
    version = doc.get("format_version")
    if not isinstance(version, int) or isinstance(version, bool) or not 1 <= version <= FORMAT_VERSION:
        raise InputError(f"{path}: format_version {version!r} is not one this fsdecouple "
                         f"reads (up to {FORMAT_VERSION})")
    return doc
