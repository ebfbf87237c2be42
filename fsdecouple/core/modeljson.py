"""The model file's JSON text: both of its forms written in one pass, and read back.

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

Reading, :func:`parse_object` parses as json does and says where each top-level value's
text lies, and :func:`canonical_body` turns that text back into the canonical form by
taking its layout out, with no float written again: the digest of a file as written is
checked without a second dump.
"""

from __future__ import annotations

import json
import re
from json.decoder import scanstring
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


_WHITESPACE = re.compile(r"[ \t\n\r]*")
# json's indented layout: the space after a key that starts a line, then each line break
# and the indentation after it.  Both start at a line break, and a JSON string holds no
# raw line break, so neither ever matches inside a string: a string that starts a line
# and is followed by ": " is a key.  (A pattern not anchored at a line break could start
# inside a string, at its closing quote, and so take a space out of the next string.)
_KEY_SPACE = re.compile(r'(\n *"(?:[^"\\\n]|\\.)*":) ')
_BREAK = re.compile(r"\n *")


def parse_object(text: str, decoder: json.JSONDecoder
                 ) -> tuple[dict[str, Any], dict[str, tuple[int, int]]] | None:
    """``(decoder.decode(text), spans)`` for a text holding one JSON object, where
    ``text[start:end]`` is the text of each top-level value (``spans[key]``); None for
    a text whose first character (after whitespace) is not ``{``.

    The top-level object is read here, each value by json's own scanner with the
    decoder's hooks, so the document is the one ``decoder.decode`` returns.  Invalid
    JSON raises ValueError or StopIteration, not always json's: a caller that names
    the error parses again with json.
    """
    i = _WHITESPACE.match(text, 0).end()
    if text[i:i + 1] != "{":
        return None
    scan, pairs, spans = decoder.scan_once, [], {}
    i = _WHITESPACE.match(text, i + 1).end()
    if text[i:i + 1] == "}":
        i += 1
    else:
        while True:
            if text[i:i + 1] != '"':
                raise ValueError("expected a key")
            key, i = scanstring(text, i + 1)
            i = _WHITESPACE.match(text, i).end()
            if text[i:i + 1] != ":":
                raise ValueError("expected ':'")
            start = _WHITESPACE.match(text, i + 1).end()
            value, i = scan(text, start)
            pairs.append((key, value))
            spans[key] = (start, i)
            i = _WHITESPACE.match(text, i).end()
            if text[i:i + 1] == ",":
                i = _WHITESPACE.match(text, i + 1).end()
            elif text[i:i + 1] == "}":
                i += 1
                break
            else:
                raise ValueError("expected ',' or '}'")
    if _WHITESPACE.match(text, i).end() != len(text):
        raise ValueError("extra data")
    hook = decoder.object_pairs_hook
    return (hook(pairs) if hook else dict(pairs)), spans


def canonical_body(text: str, spans: dict[str, tuple[int, int]], leave_out: tuple[str, ...]
                   ) -> str:
    """The canonical text of the object :func:`parse_object` read, without the top-level
    keys ``leave_out``, for a text laid out as ``json.dumps(..., indent=n, sort_keys=True)``
    lays it out.

    Only layout is taken out (line breaks, indentation, the space after a key that starts
    a line), never anything inside a string, so what is left parses to the same values.
    A text laid out otherwise (other whitespace, unsorted keys, numbers written another
    way) gives some other text: its digest does not match, and the caller dumps the
    parsed document instead.  Never the canonical text of other content.
    """
    return "{" + ",".join(_quote(k) + ":" + _BREAK.sub("", _KEY_SPACE.sub(r"\1", text[a:b]))
                          for k, (a, b) in sorted(spans.items()) if k not in leave_out) + "}"
