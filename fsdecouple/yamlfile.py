"""Reading a YAML config safely: plain data only, no duplicate keys, bounded size.

``yaml.safe_load`` builds no objects but will expand an alias bomb or nest without
end; :class:`SafeUniqueLoader` also refuses a key given twice, a document of more
than MAX_YAML_NODES nodes once aliases are expanded, and numbers Python cannot
hold.  :func:`read_yaml` reads at most CONFIG_LIMIT bytes and turns every problem
into one line.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml

from .errors import ConfigError, excerpt
from .files.inputs import CONFIG_LIMIT, read_bounded, reading


class SafeUniqueLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` (plain data only, no tags that build objects) that also
    refuses a key given twice, which YAML itself resolves silently to the last."""

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = self.construct_object(key_node, deep=deep)
            if not isinstance(key, str | int | float | bool):
                continue  # unhashable keys: SafeLoader's own error
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key '{key}'", key_node.start_mark
                )
            seen.add(key)
        return super().construct_mapping(node, deep)

    def construct_yaml_int(self, node):
        # int() refuses more than 4300 digits with a ValueError, not a YAML error,
        # and a float() of a longer int overflows: both are one line, not a traceback
        try:
            value = super().construct_yaml_int(node)
            float(value)
        except (ValueError, OverflowError):
            raise _Refused(
                f"the number {excerpt(node.value, 20)} is out of range", node.start_mark
            ) from None
        return value

    def construct_document(self, node):
        # An alias bomb (9 aliases of 9 aliases of ...) is a few lines that expand to
        # billions of values when walked or quoted: bound the expanded size first.
        if _expanded_size(node, MAX_YAML_NODES) > MAX_YAML_NODES:
            raise _Refused(
                f"more than {MAX_YAML_NODES} values once aliases are expanded (an alias bomb?)",
                node.start_mark,
            )
        return super().construct_document(node)


SafeUniqueLoader.add_constructor("tag:yaml.org,2002:int", SafeUniqueLoader.construct_yaml_int)
# YAML 1.1 wants a dot in a float, so `epsilon: 1e-4` would be the string "1e-4"
# and be refused as "expected a number"; read 1e-4, 1E5 and +2e3 as the floats a
# technician means (the resolvers are the loader's own copy, not PyYAML's global)
SafeUniqueLoader.yaml_implicit_resolvers = {
    k: list(v) for k, v in SafeUniqueLoader.yaml_implicit_resolvers.items()}
SafeUniqueLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float", re.compile(r"^[-+]?[0-9][0-9_]*[eE][-+]?[0-9]+$"),
    list("-+0123456789"))

MAX_YAML_NODES = 100_000  # a config holds about fifty


class _Refused(yaml.constructor.ConstructorError):
    """A config refused for its size or range, with its own message."""

    def __init__(self, message: str, mark):
        super().__init__(None, None, message, mark)


def _expanded_size(root, limit: int) -> int:
    """Number of nodes of the document with every alias expanded, or ``limit + 1``
    as soon as it is larger (a recursive alias expands without end)."""
    sizes: dict[int, int] = {}
    open_nodes: set[int] = set()

    def size(node) -> int:
        key = id(node)
        if key in sizes:
            return sizes[key]
        if key in open_nodes:
            return limit + 1
        open_nodes.add(key)
        total = 1
        if isinstance(node.value, list):
            for item in node.value:
                for child in item if isinstance(item, tuple) else (item,):
                    total += size(child)
                    if total > limit:
                        break
                if total > limit:
                    break
        open_nodes.discard(key)
        sizes[key] = min(total, limit + 1)
        return sizes[key]

    return size(root)


def _yaml_problem(err: yaml.YAMLError) -> str:
    problem = str(getattr(err, "problem", "") or "")
    if problem.startswith("duplicate key"):
        return problem
    if "constructor for the tag" in problem:
        tag = problem.split("tag", 1)[1].strip(" '")
        return f"YAML tag '{tag}' is not allowed (only plain data is read)"
    return f"not valid YAML ({problem})" if problem else "not valid YAML"


def read_yaml(path: Path, name: str) -> Any:
    """The parsed YAML document of a config file (``name``: the path as printed)."""
    with reading(path, "a config file (YAML)", noun="config", error=ConfigError):
        text = read_bounded(path, CONFIG_LIMIT, "a config file", ConfigError).decode("utf-8-sig")
    try:
        raw = yaml.load(text, Loader=SafeUniqueLoader)  # noqa: S506 (a SafeLoader)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        loc = f", row {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = err.problem if isinstance(err, _Refused) else _yaml_problem(err)
        raise ConfigError(f"{name}{loc}: {excerpt(problem, 200)}") from None
    except RecursionError:
        raise ConfigError(f"{name}: not a config (YAML nested too deeply)") from None
    if raw is not None and not isinstance(raw, dict):
        # e.g. `-c data.csv`: the whole file is one YAML string; quote only its start
        raise ConfigError(f"{name}: expected a mapping of settings, found "
                          f"{type(raw).__name__} {excerpt(repr(raw))}")
    return raw
