"""How figures are said in words, once for the terminal, the report and the certificate:
a count with its noun, the unit libsvm's settings are in, a cv document's output unit."""

from __future__ import annotations

from typing import Any


def plural(n: int, noun: str) -> str:
    """``noun`` for one, ``nouns`` for any other count."""
    return noun if n == 1 else f"{noun}s"


def counted(n: int, noun: str) -> str:
    """``1 repetition``, ``6 repetitions``."""
    return f"{n} {plural(n, noun)}"


def svr_unit(scaling: str, output_unit: str, full_scale: bool = False) -> str:
    """The unit of libsvm's epsilon and tolerance (gamma: per its square): ``F.S.``, the
    full-scale outputs, with ``scaling: full_scale`` or where the fit always works in
    them (``full_scale``: joint fits, more gauges than loads); else the outputs' own."""
    return "F.S." if full_scale or scaling == "full_scale" else output_unit


def unit_words(unit: str | dict) -> str:
    """A settings document's unit as words: one unit, or per channel ``{ux: V, uy: mV}``
    as ``mV/V``."""
    return "/".join(sorted({str(v) for v in unit.values()})) if isinstance(unit, dict) else str(unit)


def output_unit_of(doc: dict[str, Any]) -> str:
    """The output unit a cv document's settings were read in (``V`` before they said)."""
    return unit_words(((doc.get("settings") or {}).get("units") or {}).get("output", "V"))
