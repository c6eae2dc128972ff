"""The hardware modules' programs loaded exactly as a node loads them (``load_program_file``),
so in-process tests catch what only breaks outside a normal import."""

from __future__ import annotations

from tests.support.processes import REPO
from tokenring.node.program import load_program_file

MODULES = REPO / "modules"


def program(name: str) -> type:
    """``modules/<name>.py``'s Program class, compiled like ``tokenring node --program`` does."""
    return load_program_file(MODULES / f"{name}.py")[0]
