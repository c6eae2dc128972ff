"""The verbs' argparse pieces: types with one-line errors, the ring options, ``--json``, examples."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, NoReturn

from tokenring.contract import keys

if TYPE_CHECKING:
    import zenoh


class OneLineParser(argparse.ArgumentParser):
    """argparse with its errors on one line (what is wrong, and where to read more), exit 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


#: the longest wait or run a number of seconds may ask for (a week): beyond it is a typo
MAX_SECONDS = 7 * 24 * 3600.0


def _seconds(text: str, zero: bool) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    low_ok = value >= 0 if zero else value > 0
    if not (math.isfinite(value) and low_ok and value <= MAX_SECONDS):
        lowest = "0 or more" if zero else "above 0"
        raise argparse.ArgumentTypeError(
            f"{text} seconds: give a number {lowest} and at most {MAX_SECONDS:.0f}"
        )
    return value


def seconds(text: str) -> float:
    """An argparse type: a positive, finite number of seconds up to :data:`MAX_SECONDS`."""
    return _seconds(text, zero=False)


def non_negative_seconds(text: str) -> float:
    """An argparse type: like :func:`seconds`, 0 allowed."""
    return _seconds(text, zero=True)


def int_within(low: int, high: int) -> Callable[[str], int]:
    """An argparse type: a whole number within ``low``..``high``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number (give {low}..{high})") from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"{value} is not within {low}..{high}")
        return value

    return parse


def number_within(low: float, high: float, unit: str = "") -> Callable[[str], float]:
    """An argparse type: a finite number within ``low``..``high`` (NaN and infinities are
    refused: a comparison with NaN is always false, so no later check would catch it)."""
    span = f"{low:g}..{high:g}{f' {unit}' if unit else ''}"

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number (give {span})") from None
        if not (math.isfinite(value) and low <= value <= high):
            raise argparse.ArgumentTypeError(f"{text}: give a number within {span}")
        return value

    return parse


def positive_int(text: str) -> int:
    """An argparse type: a whole number of at least 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number (give 1 or more)") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value}: give at least 1")
    return value


def node_id(text: str) -> int:
    """An argparse type: a node ID, 1..255."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a node ID (1..255)") from None
    if not 1 <= value <= 255:
        raise argparse.ArgumentTypeError(f"{value} is not a node ID (1..255)")
    return value


def add_ring_options(parser: argparse.ArgumentParser, *, listen: bool = True) -> None:
    """--ring, --connect, --listen, --mode, --zenoh-config, --protocol."""
    group = parser.add_argument_group("ring and Zenoh")
    group.add_argument(
        "--ring",
        default=keys.DEFAULT_RING,
        type=keys.check_ring_name_type,
        help="ring name (a key namespace; default %(default)s)",
    )
    group.add_argument(
        "-e",
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help=f"Zenoh endpoint to connect to (default for tools: {keys.default_endpoint()})",
    )
    if listen:
        group.add_argument(
            "-l",
            "--listen",
            action="append",
            metavar="ENDPOINT",
            help="Zenoh endpoint to listen on",
        )
    group.add_argument(
        "--mode",
        default="peer",
        choices=("peer", "client"),
        help="Zenoh mode (default %(default)s)",
    )
    group.add_argument("--zenoh-config", metavar="FILE", help="Zenoh config file (also $ZENOH_CONFIG)")
    group.add_argument("--protocol", metavar="FILE", help="protocol.yaml to use (also $TOKENRING_PROTOCOL)")


def add_json_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="machine-readable JSON output")


def tap_session(args: argparse.Namespace, block_close_s: float | None = None) -> zenoh.Session:
    """A session for a tool joining a running ring (connects to the tap endpoint by default);
    ``block_close_s`` as :func:`tokenring.transport.zenoh_config.make_config`."""
    from tokenring.transport.zenoh_config import make_config, open_session

    connect = list(args.connect or [keys.default_endpoint()])
    config = make_config(
        mode=getattr(args, "mode", "peer"),
        connect=connect,
        listen=getattr(args, "listen", None) or [],
        config_file=getattr(args, "zenoh_config", None),
        block_close_s=block_close_s,
    )
    return open_session(config)


class ExamplesHelpFormatter(argparse.RawDescriptionHelpFormatter):
    """A verb's help: prose paragraphs wrapped to the terminal, as argparse's default does, but
    the examples and any indented block (a table, a command line) kept as written."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        paragraphs = []
        for paragraph in text.strip("\n").split("\n\n"):
            lines = paragraph.splitlines()
            if paragraph.startswith("examples:") or any(line[:1].isspace() for line in lines):
                paragraphs.append("\n".join(indent + line for line in lines))
            else:
                paragraphs.append(argparse.HelpFormatter._fill_text(self, paragraph, width, indent))
        return "\n\n".join(paragraphs)


def with_examples(examples: str) -> dict[str, Any]:
    """``add_parser`` keywords for a help that ends with ``examples`` as written (an
    ``examples:`` line, then one indented ``tokenring ...`` command a line)."""
    return {"epilog": examples, "formatter_class": ExamplesHelpFormatter}


def protocol_text(path: str | None) -> str:
    """protocol.yaml's text as the ring reads it (the file is checked by load_protocol first)."""
    from pathlib import Path

    from tokenring.contract.protocol import default_protocol_path

    return Path(path or default_protocol_path()).read_text(encoding="utf-8")
