"""The ``tokenring`` command line: the ring's verbs live in :mod:`tokenring.cli.commands`, an
application's (the robot's) come through :mod:`tokenring.extensions`.

It answers at once: ``--version`` is answered before any parser is built; a verb of the ring's own
is the parser's only verb (its module alone imported, no extension loaded unless its options come
from one); ``--help`` lists every verb by its one-line help without building its options
(:mod:`tokenring.cli.verbs`). What a verb does is imported when it runs.

Exit codes: 0 success; 1 the run failed (a node died, an invariant broke, nobody answered);
2 bad input (options, files, protocol.yaml); 130 stopped by Ctrl-C.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from tokenring import __version__
from tokenring.errors import TokenRingError

if TYPE_CHECKING:
    import argparse

Runner = Callable[["argparse.Namespace"], int]

LOG_LEVELS = ("debug", "info", "warning", "error")


def _setup_logging(level: str) -> None:
    import logging

    logging.basicConfig(
        level=getattr(logging, level.upper(), logging.INFO),
        format="%(asctime)s.%(msecs)03d %(levelname)-5s %(message)s",
        datefmt="%H:%M:%S",
        stream=sys.stderr,
    )


def version() -> str:
    """This tokenring's version (``tokenring --version``): :data:`tokenring.__version__`, the one
    the distribution is built with (pyproject.toml reads it), so no package metadata is read."""
    return __version__


def asks_version(argv: Sequence[str]) -> bool:
    """Whether ``argv`` asks for the version before anything argparse would act on first: only
    ``--log-level LEVEL`` (a valid one) may come before ``--version``. Anything else is left to the
    parser, which answers ``--version`` too, only later."""
    words = iter(argv)
    for word in words:
        if word == "--version":
            return True
        if word == "--log-level":
            level = next(words, None)
        elif word.startswith("--log-level="):
            level = word.partition("=")[2]
        else:
            return False
        if level not in LOG_LEVELS:
            return False
    return False


def requested_verb(argv: Sequence[str]) -> str | None:
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
    """The parser and each verb's runner. A verb of the ring's own (:mod:`tokenring.cli.commands`)
    is built alone: neither the other verbs nor the extensions are loaded for it (its own options
    may ask for them: ``up``'s and ``load``'s come partly from the extensions). For no verb, or one
    the ring does not know (an application's, or a typo), every verb is listed, the ring's and the
    extensions', each built only once the command line picks it (:class:`tokenring.cli.verbs.Verbs`)."""
    from tokenring.cli import commands
    from tokenring.cli.args import OneLineParser
    from tokenring.cli.verbs import Verbs

    parser = OneLineParser(
        prog="tokenring",
        description="An emulated ARCNET token-ring robot: its modules pass one 512-byte token "
        "around a ring of OS processes over Zenoh.",
        epilog="Run 'tokenring COMMAND --help' for a command's options.",
    )
    parser.add_argument(
        "--version", action="version", version=f"%(prog)s {version()}", help="show the version and exit"
    )
    parser.add_argument("--log-level", default="info", choices=LOG_LEVELS)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", action=Verbs)
    assert isinstance(sub, Verbs)
    runners: dict[str, Runner] = {}
    own = commands.names()
    if verb is not None and verb.replace("-", "_") in own:
        module = commands.verb_module(verb.replace("-", "_"))
        runners.update(dict.fromkeys(sub.build_verb(module), module.run))
        return parser, runners
    from tokenring import extensions

    modules = [commands.verb_module(name) for name in own]
    modules += [module for extension in extensions.loaded() for module in extension.commands()]
    for module in modules:
        runners.update(dict.fromkeys(sub.add_verb(module), module.run))
    return parser, runners


def _stacks_on_sigusr1() -> None:
    """`kill -USR1 PID` prints where every thread of a stuck tokenring process is, and it goes on;
    only where stderr is a real file (a caller running :func:`main` in its own process, e.g.
    under pytest's capture, keeps its signals)."""
    try:
        sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):  # io.UnsupportedOperation is an OSError
        return
    import faulthandler
    import signal

    faulthandler.register(signal.SIGUSR1, all_threads=True)


def main(argv: Sequence[str] | None = None) -> int:
    words = list(sys.argv[1:] if argv is None else argv)
    if asks_version(words):  # no parser, no verb: the version alone
        print(f"tokenring {version()}")
        return 0
    try:
        parser, runners = build_parser(requested_verb(words))
        args = parser.parse_args(words)
    except TokenRingError as exc:  # an application (extension) that fails to load
        print(f"tokenring: error: {exc}", file=sys.stderr)
        return exc.exit_code
    if not args.command:
        parser.print_help()
        return 2
    _setup_logging(args.log_level)
    _stacks_on_sigusr1()
    from tokenring.transport.zenoh_config import use_host_runtime, use_node_runtime

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
