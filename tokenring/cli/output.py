"""The verbs' output: JSON on stdout or to a file, checked before the run it reports on."""

from __future__ import annotations

import json
import sys
from typing import Any

from tokenring._util.tables import finite, json_default
from tokenring.errors import UsageError


def print_json(value: Any, stream: Any = None) -> None:
    (stream or sys.stdout).write(json.dumps(value, default=json_default) + "\n")


def write_json(target: str, value: Any) -> None:
    """A ``--json TARGET`` report: ``-`` prints it, anything else is the file to write."""
    from tokenring._util.files import write_atomically

    text = json.dumps(finite(value), indent=2, default=json_default) + "\n"
    if target == "-":
        sys.stdout.write(text)
    else:
        write_atomically(target, text)


def check_option_output(option: str, target: str, force: bool = False) -> None:
    """Refuse the output file of ``option`` (e.g. ``--logs FILE``) that cannot be written, or
    that exists (without ``--force``), before the run whose results it is for."""
    from tokenring._util.files import check_output

    check_output(target, force=force, error=lambda where, problem: UsageError(f"{option} {where}: {problem}"))


def check_json_target(target: str | None, force: bool = False) -> None:
    """:func:`check_option_output` for ``--json FILE`` (``-`` prints: nothing to check)."""
    if target and target != "-":
        check_option_output("--json", target, force)
