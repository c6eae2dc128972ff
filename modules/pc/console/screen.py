"""The operator's screen (``--ui ncurses``, the seed's NcursesUserInterface), drawn with Textual:
sensors, synchronisation, position store and action queue in four panels, the message stream
below, the last key's outcome and the keys of table 8.2 at the bottom."""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import sys
from collections.abc import Callable
from typing import Any

from rich.text import Text
from textual.app import App, ComposeResult
from textual.containers import Grid
from textual.events import Key
from textual.widgets import RichLog, Static

from modules.pc.console.keys import RELEASE_S, Ended, KeyRunner, ending_signals
from modules.pc.console.state import ConsoleState, unseen_lines
from modules.pc.operator import Outcome, keys_help

PANELS = (
    ("sensors", "Sensors: raw data (how often it changed)"),
    ("sync", "Synchronisation"),
    ("positions", "Position store"),
    ("queue", "Action queue"),
)


class ConsoleScreen(App[int]):
    """The live screen; exits with 0 on ``x``/``q``/Ctrl-C, 128 + the signal's number on SIGTERM
    or SIGHUP (:func:`run_screen` then stops the robot)."""

    CSS = """
    Grid { grid-size: 2 2; grid-columns: 3fr 2fr; height: 3fr; }
    Grid > Static { border: round $accent; padding: 0 1; height: 100%; }
    #messages { border: round $secondary; height: 2fr; }
    #status { height: 1; color: $warning; }
    #keys { height: 2; color: $text-muted; }
    """

    def __init__(
        self,
        state: ConsoleState,
        runner_for: Callable[[Callable[[Outcome], None]], KeyRunner],
        poll_main: Callable[[], None],
        title: str,
    ) -> None:
        super().__init__()
        self.state = state
        self.runner = runner_for(self._outcome_from_thread)
        self.poll_main = poll_main
        self.title_text = title
        self._shown_messages: list[str] = []
        self._polling = False
        self._loop: asyncio.AbstractEventLoop | None = None

    def compose(self) -> ComposeResult:
        with Grid():
            for name, _ in PANELS:
                yield Static(id=name)
        yield RichLog(id="messages", wrap=False, max_lines=2000)
        yield Static("", id="status")
        yield Static(keys_help(), id="keys")

    def on_mount(self) -> None:
        self.title = self.title_text
        for name, title in PANELS:
            self.query_one(f"#{name}", Static).border_title = title
        self.query_one("#messages", RichLog).border_title = "Messages"
        self._loop = asyncio.get_running_loop()
        self.runner.start()
        self.set_interval(0.25, self.redraw)
        self.set_interval(0.5, self._ask_main)
        self.redraw()

    def _ask_main(self) -> None:
        if not self._polling:
            self._polling = True
            self.run_worker(self._poll_main, thread=True, group="main")

    def _poll_main(self) -> None:
        try:
            self.poll_main()
        finally:
            self._polling = False

    def redraw(self) -> None:
        s = self.state
        for name, lines in (
            ("sensors", s.sensors_lines()),
            ("sync", s.sync_lines()),
            ("positions", s.position_lines()),
            ("queue", s.queue_lines()),
        ):
            self.query_one(f"#{name}", Static).update(Text("\n".join(lines)))
        log = self.query_one("#messages", RichLog)
        now = s.message_lines()
        fresh, earlier = unseen_lines(self._shown_messages, now)
        if earlier:  # messages from before the screen opened, behind the first live ones: in order
            log.clear()
            self._shown_messages[:] = now
            fresh = now
        for line in fresh:
            log.write(Text(line))

    def on_key(self, event: Key) -> None:
        event.stop()
        event.prevent_default()
        if event.key in ("x", "q", "X", "Q", "ctrl+c"):
            self.exit(0)
            return
        self.query_one("#status", Static).update(Text(f"{event.key} …"))
        self.runner.press(event.character if event.key not in NAMED and event.character else event.key)

    def _outcome_from_thread(self, outcome: Outcome) -> None:
        """Shown when the screen's loop gets to it: the key thread never waits for the screen
        (which, quitting, waits for the key thread)."""
        if self._loop is not None:
            with contextlib.suppress(RuntimeError):  # the loop closed: the screen is gone
                self._loop.call_soon_threadsafe(self._show, outcome)

    def _show(self, outcome: Outcome) -> None:
        mark = "" if outcome.ok else "✗ "
        with contextlib.suppress(Exception):  # the screen is being taken down
            self.query_one("#status", Static).update(Text(f"{mark}{outcome.text}"))

    def end(self, signum: int) -> None:
        """A signal in the main thread. SIGTERM: quit as ``x`` does. SIGHUP: the terminal is gone,
        and Textual's writer would wait forever to give it back: stop the robot and leave."""
        if signum == signal.SIGHUP:
            self.runner.stop(timeout=RELEASE_S, discard=True)
            os._exit(128 + signum)
        if self._loop is None or self._loop.is_closed():
            raise Ended(signum)
        self._loop.call_soon_threadsafe(self.exit, 128 + signum)


#: Textual's names of the keys table 8.2 names (the others are taken by their character)
NAMED = ("up", "down", "left", "right", "space")


def run_screen(app: ConsoleScreen, **kwargs: Any) -> int:
    """Run the screen until it quits, then stop what the keys left driving and say so on the
    terminal given back; the exit code (0, 128 + a signal's number, 1 if the screen failed)."""
    code: int | None = 1
    try:
        with ending_signals(app.end):
            code = app.run(**kwargs)
    except Ended as ended:
        code = ended.code
    finally:
        released = app.runner.stop(timeout=RELEASE_S)
        if released is not None:
            with contextlib.suppress(OSError):  # a closed terminal: nobody to tell
                print(("" if released.ok else "✗ ") + released.text, file=sys.stdout, flush=True)
    return 0 if code is None else int(code)
