"""The ``tokenring`` command line: the ring's verbs live in :mod:`tokenring.cli.commands`, an
application's (the robot's) come through :mod:`tokenring.extensions`.

Exit codes: 0 success; 1 the run failed (a node died, an invariant broke, nobody answered);
2 bad input (options, files, protocol.yaml); 130 stopped by Ctrl-C.
"""

from __future__ import annotations

import argparse
import faulthandler
import importlib
import logging
import signal
import sys
from collections.abc import Callable
from typing import Any

from tokenring.errors import TokenRingError
from tokenring.transport.zenoh_config import use_host_runtime, use_node_runtime

Runner = Callable[[argparse.Namespace], int]

#: verbs parsed without the other verbs or any extension loaded: ``node`` is the process ``up``
#: starts per module, which should import what a node needs and nothing else (no plotting, no
#: other verbs, no package metadata): 25 MB less per node process
LEAN_VERBS = ("node",)


def _setup_logging(level: str) -> None:
    logging.basicConfig(
        level=getattr(logging, level.upper(), logging.INFO),
        format="%(asctime)s.%(msecs)03d %(levelname)-5s %(message)s",
        datefmt="%H:%M:%S",
        stream=sys.stderr,
    )


def version() -> str:
    """The installed distribution's version (``tokenring --version``)."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as dist_version

    try:
        return dist_version("tokenring")
    except PackageNotFoundError:
        return "unknown (not installed)"


class _VersionAction(argparse.Action):
    """``--version``, asking the package metadata only when given (importlib.metadata is heavy)."""

    def __init__(self, option_strings: list[str], dest: str = argparse.SUPPRESS, **kwargs: Any) -> None:
        kwargs.setdefault("help", "show the version and exit")
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, *_: Any) -> None:
        print(f"{parser.prog} {version()}")
        parser.exit()


def requested_verb(argv: list[str]) -> str | None:
    """The verb ``argv`` names: its first word past the global options (None for none, or when
    help or the version is asked for first)."""
    words = iter(argv)
    for word in words:
        if word == "--log-level":
            next(words, None)
        elif word in ("-h", "--help", "--version"):
            return None
        elif not word.startswith("-"):
            return word
    return None


def build_parser(verb: str | None = None) -> tuple[argparse.ArgumentParser, dict[str, Runner]]:
    """The parser and each verb's runner: every verb, or only ``verb`` if it is a lean one
    (:data:`LEAN_VERBS`), which then needs neither the other verbs nor the extensions."""
    from tokenring.cli.args import OneLineParser

    parser = OneLineParser(
        prog="tokenring",
        description="An emulated ARCNET token-ring robot: its modules pass one 512-byte token "
        "around a ring of OS processes over Zenoh.",
        epilog="Run 'tokenring COMMAND --help' for a command's options.",
    )
    parser.add_argument("--version", action=_VersionAction)
    parser.add_argument("--log-level", default="info", choices=("debug", "info", "warning", "error"))
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    runners: dict[str, Runner] = {}
    if verb in LEAN_VERBS:
        verbs = [importlib.import_module(f"tokenring.cli.commands.{verb.replace('-', '_')}")]
    else:
        from tokenring import extensions
        from tokenring.cli.commands import discover

        verbs = discover() + [module for extension in extensions.loaded() for module in extension.commands()]
    for module in verbs:
        name = module.__name__.rsplit(".", 1)[-1].replace("_", "-")
        before = set(sub.choices)
        module.add_parser(sub)
        for added in set(sub.choices) - before:
            runners[added] = module.run
        runners.setdefault(name, module.run)
    return parser, runners


def _stacks_on_sigusr1() -> None:
    """`kill -USR1 PID` prints where every thread of a stuck tokenring process is, and it goes on;
    only where stderr is a real file (a caller running :func:`main` in its own process, e.g.
    under pytest's capture, keeps its signals)."""
    try:
        sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):  # io.UnsupportedOperation is an OSError
        return
    faulthandler.register(signal.SIGUSR1, all_threads=True)


def main(argv: list[str] | None = None) -> int:
    try:
        parser, runners = build_parser(requested_verb(sys.argv[1:] if argv is None else argv))
    except TokenRingError as exc:  # an application (extension) that fails to load
        print(f"tokenring: error: {exc}", file=sys.stderr)
        return exc.exit_code
    args = parser.parse_args(argv)
    if not args.command:
        parser.print_help()
        return 2
    _setup_logging(args.log_level)
    _stacks_on_sigusr1()
    if args.command == "node":  # a node started by hand (a launcher's nodes get it through their environment)
        use_node_runtime()
    else:
        use_host_runtime()  # the launcher's router, the tools; its nodes get NODE_RUNTIME
    try:
        return runners[args.command](args)
    except TokenRingError as exc:
        print(f"tokenring {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        return 0


if __name__ == "__main__":
    sys.exit(main())
