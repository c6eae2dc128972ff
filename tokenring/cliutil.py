"""Argument helpers and small utilities shared by the ``tokenring`` sub-commands."""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import random
import select
import signal
import socket
import sys
import threading
import time
from collections.abc import Callable, Collection
from pathlib import Path
from typing import Any, NoReturn

import msgpack
import zenoh

from tokenring import keys
from tokenring.errors import TransportError, UsageError
from tokenring.zconfig import make_config, open_session, unanswered_hint


class OneLineParser(argparse.ArgumentParser):
    """argparse with its errors on one line (what is wrong, and where to read more), exit 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


#: how long a wait for a stop sleeps at most off the main thread, where no signal's byte wakes it
SIGNAL_CHECK_S = 0.2


class StopEvent(threading.Event):
    """A process's stop flag that :func:`wait_for_stop` sleeps on without polling.

    Setting it, from any thread or a signal handler, also writes a byte to a socket the waiting
    main thread selects on; the same socket is the signal module's wake-up fd, so a signal the
    kernel hands to another thread (one of Zenoh's) wakes the main thread at once too.
    """

    def __init__(self) -> None:
        super().__init__()
        self.wake_reader, self._wake_writer = socket.socketpair()
        self.wake_reader.setblocking(False)
        self._wake_writer.setblocking(False)

    def set(self) -> None:
        """Set the flag and wake the waiter."""
        super().set()
        # a full buffer holds wake-ups already; a closing process may have shut the socket
        with contextlib.suppress(OSError):
            self._wake_writer.send(b"\0")

    @property
    def wake_fd(self) -> int:
        """The socket a signal's C handler writes to (``signal.set_wakeup_fd``)."""
        return self._wake_writer.fileno()


def wait_for_stop(stop: StopEvent, duration: float | None = None) -> bool:
    """Wait until ``stop`` is set (a signal handler sets it) or ``duration`` is up; True if
    stopped.

    The kernel may hand SIGTERM to any thread (Zenoh's Rust ones too), and then only wakes that
    one: a main thread asleep on an endless wait never runs its Python handler. The main thread
    sleeps in ``select`` on the stop flag's socket, which the signal's C handler writes to
    whichever thread took it, so an idle node never wakes; another thread (which cannot own the
    wake-up fd) waits in slices of :data:`SIGNAL_CHECK_S`.
    """
    deadline = None if duration is None else time.monotonic() + duration
    on_main = threading.current_thread() is threading.main_thread()
    previous = signal.set_wakeup_fd(stop.wake_fd, warn_on_full_buffer=False) if on_main else None
    try:
        while not stop.is_set():
            remaining = None if deadline is None else deadline - time.monotonic()
            if remaining is not None and remaining <= 0:
                return False
            if on_main:
                # the handler of a signal taken by another thread runs once this thread is back
                # in bytecode, right after select returns; its stop.set() then ends the loop
                select.select([stop.wake_reader], [], [], remaining)
                _drain(stop.wake_reader)
            else:
                stop.wait(SIGNAL_CHECK_S if remaining is None else min(SIGNAL_CHECK_S, remaining))
        return True
    finally:
        if previous is not None:
            signal.set_wakeup_fd(previous)


def _drain(reader: socket.socket) -> None:
    with contextlib.suppress(BlockingIOError, InterruptedError):
        while reader.recv(64):
            pass


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
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"{value} is not within {low}..{high}")
        return value

    return parse


def positive_int(text: str) -> int:
    """An argparse type: a whole number of at least 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
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
    ``block_close_s`` as :func:`tokenring.zconfig.make_config`."""
    connect = list(args.connect or [keys.default_endpoint()])
    config = make_config(
        mode=getattr(args, "mode", "peer"),
        connect=connect,
        listen=getattr(args, "listen", None) or [],
        config_file=getattr(args, "zenoh_config", None),
        block_close_s=block_close_s,
    )
    return open_session(config)


def discover(session: zenoh.Session, ring: str, timeout: float = 5.0, settle: float = 0.5) -> set[int]:
    """IDs of the ring's live nodes as seen from a fresh tool session.

    Peers do not route for each other: a new session reaches a node only once gossip has
    connected it to that node, which takes a moment. Wait until the set of liveliness tokens
    seen is non-empty and has not changed for ``settle`` seconds (or ``timeout`` ends)."""
    deadline = time.monotonic() + timeout
    seen: set[int] = set()
    stable_since = time.monotonic()
    while time.monotonic() < deadline:
        found = set()
        try:
            for reply in session.liveliness().get(keys.node(ring, "*"), timeout=1.0):
                if reply.ok is not None:
                    node_id = keys.id_from_key(str(reply.ok.key_expr))
                    if node_id is not None:
                        found.add(node_id)
        except zenoh.ZError as exc:
            raise TransportError(f"liveliness query failed: {exc}") from exc
        if found != seen:
            seen, stable_since = found, time.monotonic()
        elif seen and time.monotonic() - stable_since >= settle:
            break
        time.sleep(0.1)
    return seen


def query(
    session: zenoh.Session,
    key: str,
    request: Any = None,
    timeout: float = 2.0,
    enough: Callable[[list[tuple[str, Any]]], bool] | None = None,
) -> list[tuple[str, Any]]:
    """Query a control key; returns (key, decoded reply) for every answer.

    A key with a wildcard asks every matching node (and waits for all, up to ``timeout``, or
    until ``enough`` says the answers so far suffice: a hung node answers nothing); a plain key
    asks the best matching one only, so a hung node elsewhere cannot delay it."""
    payload = msgpack.packb(request) if request is not None else None
    out: list[tuple[str, Any]] = []
    wildcard = "*" in key
    try:
        options: dict[str, Any] = {
            "timeout": timeout,
            "target": zenoh.QueryTarget.ALL if wildcard else zenoh.QueryTarget.BEST_MATCHING,
            "consolidation": zenoh.ConsolidationMode.NONE,
        }
        if payload is not None:
            options["payload"] = payload
        replies = session.get(key, **options)
        for reply in replies:
            if reply.ok is not None:
                out.append((str(reply.ok.key_expr), msgpack.unpackb(reply.ok.payload.to_bytes())))
                if enough is not None and enough(out):
                    break
    except zenoh.ZError as exc:
        raise TransportError(f"query {key} failed: {exc}") from exc
    return out


def query_one(session: zenoh.Session, key: str, request: Any = None, timeout: float = 2.0) -> Any:
    """The result of one control request; raises if nobody answers or it failed."""
    replies = query(session, key, request, timeout)
    if not replies:
        raise UsageError(
            f"nobody answered {key} (is the ring running, and is --ring right{unanswered_hint()}?)"
        )
    _, reply = replies[0]
    if not reply.get("ok"):
        raise UsageError(reply.get("error", "request failed"))
    return reply.get("result")


def _ephemeral_ports() -> tuple[int, int]:
    """The kernel's range for outgoing connections' local ports (Linux; a common default elsewhere)."""
    try:
        low, high = Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()
        return int(low), int(high)
    except (OSError, ValueError):
        return 32768, 60999


def free_port(avoid: Collection[int] = ()) -> int:
    """A TCP port on 127.0.0.1 that is free right now (tests and benchmarks), and not in ``avoid``
    (ports handed out already for listeners that have not bound yet: draws are random and repeat).

    Chosen below the ephemeral range: a port the kernel handed out (``bind(0)``) can be taken a
    moment later by any process's outgoing connection, before the listener that asked for it binds.
    """
    low, _ = _ephemeral_ports()
    candidates = range(max(1024, low - 12000), low) if low > 2048 else range(20000, 30000)
    taken = set(avoid)
    for port in random.SystemRandom().sample(candidates, min(200 + len(taken), len(candidates))):
        if port in taken:
            continue
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
            try:
                sock.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def print_json(value: Any, stream: Any = None) -> None:
    (stream or sys.stdout).write(json.dumps(value, default=json_default) + "\n")


def write_json(target: str, value: Any) -> None:
    """A ``--json TARGET`` report: ``-`` prints it, anything else is the file to write."""
    from tokenring.inputfile import write_atomically

    text = json.dumps(finite(value), indent=2, default=json_default) + "\n"
    if target == "-":
        sys.stdout.write(text)
    else:
        write_atomically(target, text)


def finite(value: Any) -> Any:
    """``value`` with every NaN or infinite float (a figure with nothing to give it) as None: JSON
    has no NaN, and a script's reader (jq, JavaScript) refuses Python's."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: finite(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite(item) for item in value]
    return value


def check_option_output(option: str, target: str, force: bool = False) -> None:
    """Refuse the output file of ``option`` (e.g. ``--logs FILE``) that cannot be written, or
    that exists (without ``--force``), before the run whose results it is for."""
    from tokenring.inputfile import check_output

    check_output(target, force=force, error=lambda where, problem: UsageError(f"{option} {where}: {problem}"))


def check_json_target(target: str | None, force: bool = False) -> None:
    """:func:`check_option_output` for ``--json FILE`` (``-`` prints: nothing to check)."""
    if target and target != "-":
        check_option_output("--json", target, force)


def with_examples(examples: str) -> dict[str, Any]:
    """``add_parser`` keywords for a help that ends with ``examples`` as written."""
    return {"epilog": examples, "formatter_class": argparse.RawDescriptionHelpFormatter}


def json_default(value: Any) -> Any:
    """What ``json.dumps`` cannot write itself: numpy values and arrays, bytes (hex), sets."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, bytes):
        return value.hex()
    if isinstance(value, set | tuple):
        return list(value)
    return str(value)


def format_table(rows: list[list[Any]], headers: list[str]) -> str:
    """A plain aligned text table."""
    cells = [[str(h) for h in headers]] + [[str(c) for c in row] for row in rows]
    widths = [max(len(row[i]) for row in cells) for i in range(len(headers))]
    lines = [
        "  ".join(c.rjust(w) if _numeric(c) else c.ljust(w) for c, w in zip(row, widths, strict=True))
        for row in cells
    ]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(line.rstrip() for line in lines)


def _numeric(text: str) -> bool:
    try:
        float(text.rstrip("%x"))
        return True
    except ValueError:
        return False
