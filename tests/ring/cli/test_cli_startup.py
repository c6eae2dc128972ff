"""``tokenring`` answers at once: ``--version``, ``--help`` and a verb's ``--help`` import only what
they show — no Zenoh, numpy, msgpack, YAML or event loop, no package metadata, a ring verb without
the other verbs or the extensions. Structural, not timed: each command runs in a subprocess that
says at exit which modules it imported; how fast that is, is the benchmark's (bench/cli_start.py)."""

from __future__ import annotations

import argparse
import importlib
import importlib.metadata
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest

import tokenring
from tests.support.processes import run_tokenring
from tokenring.cli import commands
from tokenring.cli.verbs import Verbs

#: the console script's own lines, then the modules imported written to $MODULES_OUT at exit
PROBE = """
import atexit, os, sys
atexit.register(lambda: open(os.environ["MODULES_OUT"], "w").write("\\n".join(sorted(sys.modules))))
sys.argv = ["tokenring", *sys.argv[1:]]
import re
from tokenring.cli.main import main
sys.exit(main())
"""

#: what no answer of the command line imports: the transport, numbers, wire and file formats, the
#: event loop, the Foxglove SDK
NEVER = ("zenoh", "numpy", "msgpack", "yaml", "asyncio", "foxglove")
#: the installed packages' metadata: read only where the extensions are (their entry points)
METADATA = ("importlib.metadata",)
#: the ring's rooms below the CLI: what a verb's options or its run need, never a listing
ROOMS = ("tokenring.node", "tokenring.host", "tokenring.observe", "tokenring.chaos", "tokenring.perf",
         "tokenring.web", "tokenring.transport.")  # fmt: skip


def answer(
    tmp_path: Path, *args: str, env: dict[str, str] | None = None
) -> tuple[subprocess.CompletedProcess, set[str]]:
    """``tokenring ARGS`` in a subprocess: its result and the modules it had imported at exit."""
    out = tmp_path / "modules.txt"
    environment = dict(os.environ if env is None else env, MODULES_OUT=str(out))
    result = subprocess.run(
        [sys.executable, "-c", PROBE, *args], capture_output=True, text=True, env=environment, timeout=60
    )
    return result, set(out.read_text().split())


def among(modules: set[str], names: tuple[str, ...]) -> list[str]:
    """The modules of ``modules`` that are one of ``names`` or inside one (a name ending in a dot:
    only inside it)."""
    return sorted(
        m
        for m in modules
        for n in names
        if (m.startswith(n) if n.endswith(".") else m == n or m.startswith(n + "."))
    )


def flat(text: str) -> str:
    return " ".join(text.split())


def test_the_version_is_answered_before_any_parser_or_verb(tmp_path):
    result, modules = answer(tmp_path, "--version")
    assert result.returncode == 0, result.stderr
    assert result.stdout == f"tokenring {tokenring.__version__}\n"
    assert tokenring.__version__ == importlib.metadata.version("tokenring")  # one version, installed
    assert (
        among(
            modules,
            (*NEVER, *METADATA, "argparse", "tokenring.cli.commands", "tokenring.extensions", "modules"),
        )
        == []
    )
    # after a valid --log-level too; anything else is the parser's, which answers it the same
    for args in (["--log-level", "debug", "--version"], ["--log-level=error", "--version"], ["--vers"]):
        result = run_tokenring(*args)
        assert (result.returncode, result.stdout) == (0, f"tokenring {tokenring.__version__}\n"), args


def test_a_ring_verbs_help_builds_that_verb_alone(tmp_path):
    result, modules = answer(tmp_path, "status", "--help")
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("usage: tokenring status [-h] [--timeout TIMEOUT] [--json]")
    assert "ring and Zenoh:" in result.stdout
    assert among(modules, (*NEVER, *METADATA, *ROOMS, "tokenring.extensions", "modules")) == []
    assert [m for m in modules if m.startswith("tokenring.cli.commands.")] == [
        "tokenring.cli.commands.status"
    ]


@pytest.mark.parametrize("verb", commands.names())
def test_no_verbs_help_imports_zenoh_numpy_or_yaml(tmp_path, verb):
    result, modules = answer(tmp_path, verb, "--help")
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith(f"usage: tokenring {verb} ")
    assert among(modules, NEVER) == []
    if verb not in (
        "up",
        "load",
        "web",
        "sim",
    ):  # their options come partly from the extensions (the robot's)
        assert among(modules, (*METADATA, "tokenring.extensions", "modules")) == [], verb


def test_up_help_has_the_extensions_options_and_nothing_they_run(tmp_path):
    result, modules = answer(tmp_path, "up", "--help")
    assert result.returncode == 0, result.stderr
    assert "--world NAME|FILE" in result.stdout and "--record FILE.mcap" in result.stdout
    assert among(modules, (*NEVER, "tokenring.host", "tokenring.node", "tokenring.observe")) == []


def test_the_full_help_lists_every_verb_by_its_one_line_help(tmp_path):
    result, modules = answer(tmp_path, "--help")
    assert result.returncode == 0, result.stderr
    text = flat(result.stdout)
    for name in commands.names():
        assert flat(commands.verb_module(name).HELP) in text, name
    assert " explore " in text and " replay " in text  # the robot's, through its extension
    assert among(modules, (*NEVER, *ROOMS)) == []  # no verb's options were built


def test_no_command_prints_the_help_and_a_bad_one_is_one_line():
    bare = run_tokenring()
    assert bare.returncode == 2 and bare.stdout.startswith("usage: tokenring ")
    typo = run_tokenring("stauts")
    assert typo.returncode == 2 and len(typo.stderr.splitlines()) == 1
    assert (
        "invalid choice: 'stauts'" in typo.stderr and "'status'" in typo.stderr and "'explore'" in typo.stderr
    )


def test_a_verb_the_command_line_names_only_later_is_built_in_full():
    # --log-l (argparse's abbreviation of --log-level) hides the verb from the first look: every
    # verb is listed, and status is built once the parser picks it
    result = run_tokenring("--log-l", "warning", "status", "--help")
    assert result.returncode == 0, result.stderr
    assert "--timeout TIMEOUT" in result.stdout


def test_every_ring_verb_adds_its_own_verb_with_its_help():
    for name in commands.names():
        module = commands.verb_module(name)
        sub = argparse.ArgumentParser(prog="tokenring").add_subparsers(action=Verbs)
        assert isinstance(sub, Verbs)
        assert sub.build_verb(module) == [name.replace("_", "-")], name
        (row,) = sub._get_subactions()
        assert row.help == module.HELP, name


def test_a_module_whose_help_promises_another_verb_is_one_clear_line():
    module = ModuleType("tools.shout")
    module.HELP = "shout"
    module.add_parser = lambda sub: sub.add_parser("yell", help="shout")
    parser = argparse.ArgumentParser(prog="tokenring")
    sub = parser.add_subparsers(dest="command", action=Verbs)
    assert isinstance(sub, Verbs)
    assert sub.add_verb(module) == ["shout"]
    with pytest.raises(tokenring.UsageError, match=r"tools\.shout has HELP but adds yell, not 'shout'"):
        parser.parse_args(["shout"])
