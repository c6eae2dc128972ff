"""The seed's other two user interfaces: ``stdout`` (StdoutUserInterface: only the messages, as
lines on standard output, and what each key did) and ``none`` (nothing shown). Keys are read from
the terminal one at a time (no Enter); from a pipe, each word of a line is a key's name (``up``,
``space``, ``a``)."""

from __future__ import annotations

import contextlib
import os
import select
import sys
import termios
import threading
import time
import tty
from collections.abc import Iterator
from typing import TextIO

from modules.pc.console.keys import RELEASE_S, Ended, KeyRunner, ending_signals
from modules.pc.console.state import ConsoleState, unseen_lines
from modules.pc.operator import Operator, Outcome

#: a terminal's escape sequences for the arrow keys
ARROWS = {b"\x1b[A": "up", b"\x1b[B": "down", b"\x1b[C": "right", b"\x1b[D": "left"}
#: from a pipe, how long the localisation's messages are waited for at the end
PIPE_PATIENCE_S = 5.0
#: from a pipe, how long the keys before ``x`` may take (a slow ring: seconds each)
PIPE_KEYS_S = 120.0
ARROWS.update({b"\x1bOA": "up", b"\x1bOB": "down", b"\x1bOC": "right", b"\x1bOD": "left"})


def terminal_keys(fd: int, stop: threading.Event) -> Iterator[str]:
    """Keys from a terminal in cbreak mode (restored afterwards); Ctrl-C still interrupts."""
    saved = termios.tcgetattr(fd)
    tty.setcbreak(fd)
    try:
        while not stop.is_set():
            ready, _, _ = select.select([fd], [], [], 0.2)
            if not ready:
                continue
            data = os.read(fd, 16)
            if not data:
                return
            if data.startswith(b"\x1b"):
                name = ARROWS.get(data[:3])
                yield name if name else "escape"
                continue
            for char in data.decode("utf-8", "replace"):
                yield "space" if char == " " else char
    finally:
        with contextlib.suppress(OSError, termios.error):  # a terminal gone (SIGHUP) keeps nothing
            termios.tcsetattr(fd, termios.TCSADRAIN, saved)


def line_keys(stream: TextIO) -> Iterator[str]:
    """Keys from a pipe: every word of every line is one key's name."""
    for line in stream:
        yield from line.split()


def run_plain(
    state: ConsoleState,
    operator: Operator,
    show: bool,
    out: TextIO = sys.stdout,
    keys: Iterator[str] | None = None,
    poll_s: float = 0.5,
) -> int:
    """Take keys until ``x``/``q`` (or the end of the input, Ctrl-C, SIGTERM, SIGHUP); print
    messages and outcomes when ``show`` (``stdout``), nothing otherwise (``none``). At the end
    the robot is stopped if the keys left it driving. The exit code: 0, or 128 + the signal's."""
    stop = threading.Event()
    shown: list[str] = []
    lock = threading.Lock()

    def say(text: str) -> None:
        if show:
            with lock, contextlib.suppress(OSError):  # a closed terminal: nobody to tell
                print(text, file=out, flush=True)

    def outcome(result: Outcome) -> None:
        say(("" if result.ok else "✗ ") + result.text)

    def follow() -> None:
        while not stop.wait(poll_s):
            for line in unseen_lines(shown, state.message_lines())[0]:
                say(line)

    def drain(patience_s: float) -> None:
        """The messages not shown yet; from a pipe, the localisation's (earlier ones included)
        are waited for a moment: a script's keys may all be taken before they arrive."""
        deadline = time.monotonic() + patience_s
        while time.monotonic() < deadline and not (state.localization is not None and state.message_lines()):
            time.sleep(0.1)
        for line in unseen_lines(shown, state.message_lines())[0]:
            say(line)

    runner = KeyRunner(operator, outcome).start()
    piped = keys is None and not sys.stdin.isatty()
    follower = threading.Thread(target=follow, name="console-messages", daemon=True)
    follower.start()
    if keys is None:
        keys = terminal_keys(sys.stdin.fileno(), stop) if sys.stdin.isatty() else line_keys(sys.stdin)
    quit_key, code = False, 0
    try:
        with ending_signals(), contextlib.suppress(KeyboardInterrupt):
            for key in keys:
                if key.lower() in ("x", "q"):
                    quit_key = True
                    break
                runner.press(key)
    except Ended as ended:
        code = ended.code
    finally:
        # the keys before x are carried out first (a pipe's too); a signal drops those not begun
        released = runner.stop(timeout=PIPE_KEYS_S if piped and not code else RELEASE_S, discard=bool(code))
        stop.set()
        follower.join(timeout=2.0)
        drain(PIPE_PATIENCE_S if piped and not code else 0.0)
        if released is not None:
            outcome(released)
        if quit_key:
            say("quit")
    return code
