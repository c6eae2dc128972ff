"""The ring's public faces: every package that applications import from lists its names in
``__all__``, each of them resolves, and the robot, the benchmarks and the pingpong example import
nothing else (httpx's ``tests/meta/test_exported_members.py``, one face per package)."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

from tests.support.processes import REPO

RING = REPO / "tokenring"
#: the applications of the ring: they may use its faces only
APPLICATIONS = [REPO / "modules", REPO / "bench", REPO / "tests" / "pingpong"]


def faces() -> dict[str, Path]:
    """Every package of tokenring whose ``__init__.py`` declares ``__all__``, by dotted name."""
    found = {}
    for init in sorted(RING.rglob("__init__.py")):
        if "__all__" in init.read_text():
            found[".".join(init.relative_to(REPO).parent.parts)] = init
    return found


def type_checking_names(init: Path) -> set[str]:
    """The names a face imports for the type checker (its ``if TYPE_CHECKING:`` block)."""
    names: set[str] = set()
    for node in ast.parse(init.read_text()).body:
        if isinstance(node, ast.If) and ast.unparse(node.test) == "TYPE_CHECKING":
            for statement in node.body:
                if isinstance(statement, ast.ImportFrom):
                    names |= {alias.asname or alias.name for alias in statement.names}
    return names


def test_the_ring_has_its_faces() -> None:
    assert {
        "tokenring",
        "tokenring.cli",
        "tokenring.host",
        "tokenring.observe",
        "tokenring.transport",
    } <= set(faces())


@pytest.mark.parametrize("face", sorted(faces()))
def test_every_exported_name_resolves_and_is_typed(face: str) -> None:
    module = importlib.import_module(face)
    exported = module.__all__
    assert len(exported) == len(set(exported)), f"{face}.__all__ names a name twice"
    for name in exported:
        assert getattr(module, name) is not None, f"{face}.{name}"
    assert set(exported) == type_checking_names(faces()[face]), (
        f"{face}: __all__ and the names the type checker sees differ"
    )
    assert set(exported) <= set(dir(module))


def test_a_name_outside_a_face_is_an_attribute_error() -> None:
    import tokenring

    with pytest.raises(AttributeError, match="no attribute 'NoSuchName'"):
        tokenring.NoSuchName  # noqa: B018


def imports_of_the_ring(root: Path) -> list[tuple[str, str, str]]:
    """(where, module, name) of every ``from tokenring... import name`` below ``root``."""
    found = []
    for path in sorted(root.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "tokenring":
                for alias in node.names:
                    found.append((f"{path.relative_to(REPO)}:{node.lineno}", node.module, alias.name))
    return found


@pytest.mark.parametrize("root", APPLICATIONS, ids=lambda p: str(p.relative_to(REPO)))
def test_applications_import_only_exported_names(root: Path) -> None:
    exported = {face: set(importlib.import_module(face).__all__) for face in faces()}
    wrong = [
        f"{where}: from {module} import {name}"
        for where, module, name in imports_of_the_ring(root)
        if name not in exported.get(module, set())
    ]
    assert not wrong, "not in a face's __all__:\n" + "\n".join(wrong)
