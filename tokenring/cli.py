"""The ``tokenring`` command line: the ring's verbs live in :mod:`tokenring.commands`, an
application's (the robot's) come through :mod:`tokenring.extensions`.

Exit codes: 0 success; 1 the run failed (a node died, an invariant broke, nobody answered);
2 bad input (options, files, protocol.yaml); 130 stopped by Ctrl-C.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Callable

from tokenring.errors import TokenRingError
from tokenring.zconfig import use_node_runtime

Runner = Callable[[argparse.Namespace], int]


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


def build_parser() -> tuple[argparse.ArgumentParser, dict[str, Runner]]:
    from tokenring import extensions
    from tokenring.cliutil import OneLineParser
    from tokenring.commands import discover

    parser = OneLineParser(
        prog="tokenring",
        description="An emulated ARCNET token-ring robot: its modules pass one 512-byte token "
        "around a ring of OS processes over Zenoh.",
        epilog="Run 'tokenring COMMAND --help' for a command's options.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {version()}")
    parser.add_argument("--log-level", default="info", choices=("debug", "info", "warning", "error"))
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    runners: dict[str, Runner] = {}
    verbs = discover() + [module for extension in extensions.loaded() for module in extension.commands()]
    for module in verbs:
        name = module.__name__.rsplit(".", 1)[-1].replace("_", "-")
        before = set(sub.choices)
        module.add_parser(sub)
        for added in set(sub.choices) - before:
            runners[added] = module.run
        runners.setdefault(name, module.run)
    return parser, runners


def main(argv: list[str] | None = None) -> int:
    try:
        parser, runners = build_parser()
    except TokenRingError as exc:  # an application (extension) that fails to load
        print(f"tokenring: error: {exc}", file=sys.stderr)
        return exc.exit_code
    args = parser.parse_args(argv)
    if not args.command:
        parser.print_help()
        return 2
    _setup_logging(args.log_level)
    use_node_runtime()  # the launcher's router and every node it starts
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
