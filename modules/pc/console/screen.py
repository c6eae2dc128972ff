"""The operator's screen (``--ui ncurses``, the seed's NcursesUserInterface), drawn with Textual:
sensors, synchronisation, position store and action queue in four panels, the message stream
below, the last key's outcome and the keys of table 8.2 at the bottom."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rich.text import Text
from textual.app import App, ComposeResult
from textual.containers import Grid
from textual.events import Key
from textual.widgets import RichLog, Static

from modules.pc.console.keys import KeyRunner
from modules.pc.console.state import ConsoleState
from modules.pc.operator import Outcome, keys_help

PANELS = (
    ("sensors", "Sensors: raw data (how often it changed)"),
    ("sync", "Synchronisation"),
    ("positions", "Position store"),
    ("queue", "Action queue"),
)


class ConsoleScreen(App[int]):
    """The live screen; exits with 0 on ``x``/``q``/Ctrl-C."""

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
        for line in new_lines(self._shown_messages, s.message_lines()):
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
        self.call_from_thread(self._show, outcome)

    def _show(self, outcome: Outcome) -> None:
        mark = "" if outcome.ok else "✗ "
        self.query_one("#status", Static).update(Text(f"{mark}{outcome.text}"))

    def on_unmount(self) -> None:
        self.runner.stop(timeout=2.0)


#: Textual's names of the keys table 8.2 names (the others are taken by their character)
NAMED = ("up", "down", "left", "right", "space")


def new_lines(shown: list[str], now: list[str]) -> list[str]:
    """The lines of ``now`` after the last one already ``shown`` (a bounded list moves on), and
    remember them as shown."""
    if not shown:
        fresh = now
    else:
        last = shown[-1]
        try:
            fresh = now[len(now) - 1 - now[::-1].index(last) + 1 :]
        except ValueError:
            fresh = now
    shown.extend(fresh)
    del shown[:-500]
    return fresh


def run_screen(app: ConsoleScreen, **kwargs: Any) -> int:
    """Run the screen until it quits; its exit code (0 unless it failed)."""
    code = app.run(**kwargs)
    return 0 if code is None else int(code)
