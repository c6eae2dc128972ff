"""User programs: what runs on a node beside the OS, and how a program's source is loaded.

A program is one Python file defining a class ``Program`` derived from :class:`UserProgram`.
The node OS calls ``setup()`` then ``run()`` in the program's own thread; ``run`` returns when
:attr:`UserProgram.running` turns false. Programs reach other modules only through the token
(``self.os``) and their hardware only through ``self.hw`` (set by the node process).
"""

from __future__ import annotations

import sys
import types
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tokenring import runtime
from tokenring.errors import ProgramError

if TYPE_CHECKING:
    from tokenring.node.node_os import NodeOS


class UserProgram:
    """Base class of a module's user program."""

    #: the module this program is written for (checked against the node it is loaded into)
    module: str = ""

    def __init__(self, os: NodeOS, hardware: Any = None) -> None:
        self.os = os
        self.hw = hardware
        self.stop_requested = runtime.current().event()

    @property
    def running(self) -> bool:
        return not self.stop_requested.is_set() and not self.os.stopping

    def sleep(self, seconds: float) -> bool:
        """Sleep unless asked to stop; returns False if the program should end."""
        return not self.stop_requested.wait(seconds) and not self.os.stopping

    def setup(self) -> None:
        """Register channels (``self.os.subscribe``, ``publish``, ``set_own_input_id``)."""

    def run(self) -> None:
        """The program's loop; the default just follows the token until stopped."""
        while self.running:
            self.os.wait_visit(0.5)

    def teardown(self) -> None:
        """Release what ``setup`` took (hardware handles, files)."""

    def report(self) -> dict[str, Any]:
        """What the program wants to tell tools (``tokenring status``, tests); plain values."""
        return {}


def program_sha256(source: bytes) -> bytes:
    """The end-to-end integrity hash of a program (SHA-256). hashlib is imported here, when a
    program moves: it loads OpenSSL, 3-4 MB of the RSS of a node that runs none (issue 23)."""
    import hashlib

    return hashlib.sha256(source).digest()


def program_digest(source: bytes) -> str:
    """:func:`program_sha256` in hex."""
    return program_sha256(source).hex()


def load_program(source: bytes | str, filename: str = "<program>") -> type[UserProgram]:
    """Compile a program's source and return its ``Program`` class; raises :class:`ProgramError`."""
    # a byte-order mark (Windows editors write one) is no Python: compile() refuses U+FEFF in text
    text = source.decode("utf-8-sig") if isinstance(source, bytes) else source.removeprefix("\ufeff")
    module_name = f"tokenring_program_{Path(filename).stem}"
    module = types.ModuleType(module_name)
    module.__file__ = filename
    # registered like an imported module, so that dataclasses, pickling and typing.get_type_hints
    # in a program (which look the module up by name) work as they would in any import
    sys.modules[module_name] = module
    try:
        code = compile(text, filename, "exec")
    except SyntaxError as exc:
        raise ProgramError(f"{filename}:{exc.lineno}: syntax error: {exc.msg}") from None
    try:
        exec(code, module.__dict__)
    except Exception as exc:
        raise ProgramError(f"{filename}: importing the program failed: {type(exc).__name__}: {exc}") from None
    program = module.__dict__.get("Program")
    if not (isinstance(program, type) and issubclass(program, UserProgram)):
        raise ProgramError(f"{filename}: no class Program(UserProgram) found; this is not a module program")
    return program


def inspect_program(source: bytes | str, filename: str = "<program>") -> str:
    """Check a program without running it (the PC side of ``load``: an operator's file must
    not execute on the operator's machine): UTF-8, valid Python, a top-level
    ``class Program`` with a base class. Returns its ``module = "..."`` (the node it is for),
    or ``""``. Raises :class:`ProgramError` naming the file and line."""
    import ast

    if isinstance(source, bytes):
        try:
            text = source.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            line = source.count(b"\n", 0, exc.start) + 1
            raise ProgramError(f"{filename}:{line}: not UTF-8 text (byte {exc.start})") from None
    else:
        text = source.removeprefix("\ufeff")
    try:
        tree = ast.parse(text, filename)
    except SyntaxError as exc:
        raise ProgramError(f"{filename}:{exc.lineno}: syntax error: {exc.msg}") from None
    except (ValueError, RecursionError, MemoryError) as exc:  # NUL bytes, absurd nesting
        raise ProgramError(f"{filename}: not a Python program ({type(exc).__name__})") from None
    program = next(
        (node for node in tree.body if isinstance(node, ast.ClassDef) and node.name == "Program"), None
    )
    if program is None or not program.bases:
        raise ProgramError(f"{filename}: no class Program(UserProgram) found; this is not a module program")
    for statement in program.body:
        if (
            isinstance(statement, ast.Assign)
            and any(isinstance(t, ast.Name) and t.id == "module" for t in statement.targets)
            and isinstance(statement.value, ast.Constant)
            and isinstance(statement.value.value, str)
        ):
            return statement.value.value
    return ""


def load_program_file(path: str | Path) -> tuple[type[UserProgram], bytes]:
    """Read and load a program file; returns the class and the exact bytes read."""
    from tokenring._util.files import message_error, read_bytes

    file = Path(path)
    source = read_bytes(file, "program file", message_error(ProgramError))
    return load_program(source, str(file)), source
