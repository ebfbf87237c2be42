"""The model file's JSON text, written in one pass for both of its forms.

A model file is ``json.dumps(doc, indent=1, sort_keys=True, allow_nan=False)`` and its
digest covers the canonical ``json.dumps(body, sort_keys=True, separators=(",", ":"),
allow_nan=False)`` (:func:`fsdecouple.core.modelfile.content_digest`).  Python's json
writes an indented document with its pure-Python encoder, one generator step per
float; and writing both forms turns every float into text twice, the cost of either
dump (~0.5 us a float; a six-axis model holds ~10^5).  :func:`dump_forms` writes the
two forms at once, byte for byte what json writes: the arrays of numbers that make up
a model's bulk go through json's C encoder once, and their indented form is that text
with a line break after each comma (a list of numbers holds no string, so no comma
there is inside one).  Anything it does not write the way json would (a non-string
key, a NaN, a type json does not know) leaves the whole document to json itself,
which writes or refuses it as always.
"""

from __future__ import annotations

import json
from json.encoder import encode_basestring_ascii as _quote
from typing import Any

_NUMBERS = json.JSONEncoder(allow_nan=False, separators=(",", ":"))
_NUMBER_TYPES = frozenset({float, int})
_INFINITIES = (float("inf"), float("-inf"))


class _LeftToJson(Exception):
    """A value written the reference way (json.dumps), which may refuse it."""


def dump_forms(doc: dict[str, Any], leave_out: tuple[str, ...]) -> tuple[str, dict[str, str]]:
    """``(canonical, indented)``: the canonical text of ``doc`` without the top-level keys
    ``leave_out``, and the indented text of each top-level value (for :func:`join_indented`).

    Raises ValueError or TypeError as json.dumps does for a document json cannot write.
    """
    try:
        canonical, indented = [], {}
        for key in sorted(doc):
            if not isinstance(key, str):
                raise _LeftToJson
            compact, pretty = [], []
            _encode(doc[key], "\n ", compact, pretty)
            if key not in leave_out:
                canonical.append(_quote(key) + ":" + "".join(compact))
            indented[key] = "".join(pretty)
        return "{" + ",".join(canonical) + "}", indented
    except _LeftToJson:
        body = {k: v for k, v in doc.items() if k not in leave_out}
        return (json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False),
                {k: json.dumps(v, indent=1, sort_keys=True, allow_nan=False).replace("\n", "\n ")
                 for k, v in doc.items()})


def join_indented(indented: dict[str, str]) -> str:
    """The indented document of top-level values written by :func:`dump_forms`."""
    if not indented:
        return "{}"
    return "{\n" + ",\n".join(f" {_quote(k)}: {indented[k]}" for k in sorted(indented)) + "\n}"


def _encode(value: Any, newline: str, compact: list[str], pretty: list[str]) -> None:
    """Append ``value``'s canonical text to ``compact`` and its indented text (nested at
    ``newline``) to ``pretty``, in the order of json's own encoder's type checks."""
    if isinstance(value, str):
        text = _quote(value)
    elif value is None:
        text = "null"
    elif value is True:
        text = "true"
    elif value is False:
        text = "false"
    elif isinstance(value, int):
        text = int.__repr__(value)
    elif isinstance(value, float):
        if value != value or value in _INFINITIES:
            raise _LeftToJson
        text = float.__repr__(value)
    elif isinstance(value, list | tuple):
        if not value:
            text = "[]"
        elif set(map(type, value)) <= _NUMBER_TYPES:
            try:
                text = _NUMBERS.encode(value)
            except ValueError:  # NaN or infinity
                raise _LeftToJson from None
            inner = newline + " "
            compact.append(text)
            pretty.append("[" + inner + text[1:-1].replace(",", "," + inner) + newline + "]")
            return
        else:
            inner = newline + " "
            compact.append("[")
            pretty.append("[" + inner)
            for i, v in enumerate(value):
                if i:
                    compact.append(",")
                    pretty.append("," + inner)
                _encode(v, inner, compact, pretty)
            compact.append("]")
            pretty.append(newline + "]")
            return
    elif isinstance(value, dict):
        if not value:
            text = "{}"
        else:
            if not all(isinstance(k, str) for k in value):
                raise _LeftToJson
            inner = newline + " "
            compact.append("{")
            pretty.append("{" + inner)
            for i, k in enumerate(sorted(value)):
                key = _quote(k)
                compact.append("," + key + ":" if i else key + ":")
                pretty.append("," + inner + key + ": " if i else key + ": ")
                _encode(value[k], inner, compact, pretty)
            compact.append("}")
            pretty.append(newline + "}")
            return
    else:
        raise _LeftToJson
    compact.append(text)
    pretty.append(text)
