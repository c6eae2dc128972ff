"""Strict YAML for tokenring's own files: duplicate keys refused, every entry's line known.

PyYAML silently keeps the last of two equal keys; a typo'd scenario or config must not be
half-read. :func:`load_yaml` returns the data and, for error messages, the line of each entry
by its dotted path (``faults.2.kind`` → 14).

Every loader here refuses, while it composes and before anything is built, a document that
would take unbounded time or memory to use: an alias inside the collection it names (a
recursive structure: walking it never ends), aliases that expand the document far beyond what
its text spells out (a "billion laughs": 545 bytes that stand for a billion nodes), and
nesting deeper than :data:`MAX_DEPTH` (PyYAML's composer recurses once per level).
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


#: the deepest nesting of collections a document may have (tokenring's files need a handful)
MAX_DEPTH = 64
#: how many nodes the aliases of one document may add to the nodes its text spells out
MAX_ALIAS_NODES = 100_000


class YAMLStructureError(yaml.composer.ComposerError):
    """A document refused for its shape, not its syntax: recursive, exploding or too deep."""

    def __init__(self, problem: str, mark: yaml.Mark | None) -> None:
        super().__init__(None, None, problem, mark)


def yaml_problem(exc: yaml.MarkedYAMLError) -> str:
    """What is wrong, for a message after ``file:line:``: a syntax error says so."""
    if isinstance(exc, YAMLStructureError):
        return str(exc.problem)
    return f"YAML syntax error: {exc.problem or exc.context}"


class NumberLoader(yaml.SafeLoader):
    """SafeLoader reading numbers as YAML 1.2 does: PyYAML (YAML 1.1) takes ``1e9`` and
    ``1e300`` for text, because its floats need a dot; a user who writes them means numbers.

    It composes within bounds (:class:`YAMLStructureError`): no alias inside the collection it
    names, at most :data:`MAX_ALIAS_NODES` nodes added by aliases, at most :data:`MAX_DEPTH`
    levels."""

    def __init__(self, stream: Any) -> None:
        super().__init__(stream)
        self._depth = 0
        self._open: set[str] = set()  # anchors of the collections being composed
        self._sizes: dict[str, int] = {}  # anchor -> nodes of its node with every alias expanded
        self._expanded = 0  # nodes composed so far, each alias counted as the nodes it stands for
        self._added = 0  # of these, the ones aliases add to what the text spells out

    def compose_document(self) -> yaml.Node | None:
        node = super().compose_document()
        self._sizes.clear()
        self._expanded = self._added = 0
        return node

    def compose_node(self, parent: yaml.Node | None, index: Any) -> yaml.Node:
        event = self.peek_event()
        anchor = event.anchor
        if isinstance(event, yaml.AliasEvent):
            if anchor in self._open:
                raise YAMLStructureError(
                    f"alias *{anchor} is inside the collection &{anchor} it names: "
                    "a recursive structure, which tokenring does not read",
                    event.start_mark,
                )
            node = super().compose_node(parent, index)  # (an undefined alias: PyYAML's error)
            size = self._sizes.get(str(anchor), 1)
            self._expanded += size
            self._added += size - 1
            if self._added > MAX_ALIAS_NODES:
                raise YAMLStructureError(
                    f"aliases expand this document by more than {MAX_ALIAS_NODES} nodes beyond its "
                    f"text (*{anchor} stands for {size}): an alias bomb, which tokenring does not read",
                    event.start_mark,
                )
            return node
        if self._depth >= MAX_DEPTH:
            raise YAMLStructureError(f"nested deeper than {MAX_DEPTH} levels", event.start_mark)
        collection = isinstance(event, yaml.CollectionStartEvent)
        if collection and anchor is not None:
            self._open.add(anchor)
        before = self._expanded
        self._expanded += 1
        self._depth += 1
        try:
            node = super().compose_node(parent, index)
        finally:
            self._depth -= 1
            if collection and anchor is not None:
                self._open.discard(anchor)
        if anchor is not None:
            self._sizes[anchor] = self._expanded - before
        return node


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
        raise UsageError(f"{source}{where}: {yaml_problem(exc)}") from None
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
