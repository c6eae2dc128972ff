"""Strict YAML for tokenring's own files: duplicate keys refused, every entry's line known.

PyYAML silently keeps the last of two equal keys; a typo'd scenario or config must not be
half-read. :func:`load_yaml` returns the data and, for error messages, the line of each entry
by its dotted path (``faults.2.kind`` → 14).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml

from tokenring.errors import UsageError


def one_line(exc: BaseException) -> str:
    """An exception's text on one line (PyYAML's reader errors span several)."""
    return " ".join(str(exc).split())


class NumberLoader(yaml.SafeLoader):
    """SafeLoader reading numbers as YAML 1.2 does: PyYAML (YAML 1.1) takes ``1e9`` and
    ``1e300`` for text, because its floats need a dot; a user who writes them means numbers."""


NumberLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+
        |[-+]?(?:[0-9][0-9_]*)\.[0-9_]*
        |[-+]?\.[0-9][0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.X,
    ),
    list("-+0123456789."),
)


def strict_loader(fail: type[Exception] = UsageError, source: str = "<yaml>") -> type[yaml.SafeLoader]:
    """A loader that reads numbers as YAML 1.2 (:class:`NumberLoader`) and raises ``fail`` on
    duplicate keys, naming both lines."""

    class StrictLoader(NumberLoader):
        pass

    def construct_mapping(loader: yaml.SafeLoader, node: yaml.MappingNode) -> dict:
        seen: dict[Any, int] = {}
        for key_node, _ in node.value:
            key = loader.construct_object(key_node)
            line = key_node.start_mark.line + 1
            if key in seen:
                message = f"duplicate key {key!r} (first at line {seen[key]})"
                if fail is UsageError:
                    raise UsageError(f"{source}:{line}: {message}")
                raise fail(source, f"line {line}", message)
            seen[key] = line
        return loader.construct_mapping(node)

    StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, construct_mapping)
    return StrictLoader


def _lines(node: yaml.Node, path: str, out: dict[str, int]) -> None:
    out[path] = node.start_mark.line + 1
    if isinstance(node, yaml.MappingNode):
        for key_node, value_node in node.value:
            key = getattr(key_node, "value", "?")
            child = f"{path}.{key}" if path else str(key)
            out[child] = key_node.start_mark.line + 1
            _lines(value_node, child, out)
    elif isinstance(node, yaml.SequenceNode):
        for index, item in enumerate(node.value):
            _lines(item, f"{path}.{index}" if path else str(index), out)


def load_yaml(text: str, source: str = "<yaml>") -> tuple[Any, dict[str, int]]:
    """Parse strictly; returns (data, line of every dotted path). Errors name file and line."""
    try:
        data = yaml.load(text, Loader=strict_loader(UsageError, source))
        root = yaml.compose(text, Loader=NumberLoader)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        where = f":{mark.line + 1}:{mark.column + 1}" if mark else ""
        raise UsageError(f"{source}{where}: YAML syntax error: {exc.problem}") from None
    except yaml.YAMLError as exc:  # e.g. a control character the YAML reader refuses
        raise UsageError(f"{source}: not YAML text: {one_line(exc)}") from None
    lines: dict[str, int] = {}
    if root is not None:
        _lines(root, "", lines)
    return data, lines


def read_yaml(path: str | Path) -> tuple[Any, dict[str, int]]:
    """Read and parse a YAML file; a missing or unreadable file is a clear :class:`UsageError`."""
    from tokenring._util.files import read_text

    file = Path(path)
    return load_yaml(read_text(file, "YAML file"), str(file))
