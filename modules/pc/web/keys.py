"""The seed's keys (table 8.2) in the web view: the page posts each key it has focus for, the ring's
web server hands it to the one :class:`RobotKeys` of the ring it serves, and that carries it out
with an :class:`~modules.pc.operator.Operator`, as ``tokenring console`` does (the same held speed,
renewed while held; the same answers). A browser has nothing to quit: ``x``/``q`` say so. The
server renews the held speed only while a page is connected, and releases it (the robot stops)
when the last page goes.

``tokenring web --action FILE`` (up to three) binds the action files to ``a``, ``b``, ``c``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from tokenring import UsageError, WebKey, WebKeys

#: the browser's ``KeyboardEvent.key`` of the keys table 8.2 names by word
BROWSER = {"space": " ", "up": "ArrowUp", "down": "ArrowDown", "left": "ArrowLeft", "right": "ArrowRight"}
#: what ``x``/``q`` answer in a browser
NOTHING_TO_QUIT = (
    "nothing to quit in a browser: close the tab (the ring goes on; the robot stops with the last page)"
)
MAX_FILES = 3
#: how often the server offers the held speed for renewal (the operator renews it every second)
RENEW_POLL_S = 0.25


def add_options(parser: argparse.ArgumentParser) -> None:
    """``tokenring web``'s options for the robot's keys."""
    group = parser.add_argument_group("the robot's keys (seed table 8.2; focus on the page)")
    group.add_argument(
        "--action",
        action="append",
        default=[],
        metavar="FILE",
        help="an action file for the key a, then b, then c (up to three; seed §6.7)",
    )


def action_files(args: argparse.Namespace) -> list[str]:
    """The ``--action`` files, checked (each parsed; a bad one named by file and line)."""
    files = list(getattr(args, "action", None) or [])
    if len(files) > MAX_FILES:
        raise UsageError(f"--action takes up to three files (a, b, c), got {len(files)}")
    from modules.navigation.actions import load_actions

    for file in files:
        if not Path(file).is_file():
            raise UsageError(f"--action {file}: no such file")
        load_actions(file)
    return files


def web_keys(args: argparse.Namespace) -> WebKeys:
    """The keyboard of the robot's web view, its action files bound."""
    from modules.pc.operator import KEYS

    files = action_files(args)
    listed: list[WebKey] = []
    for key in KEYS:
        if key.name == "q":
            continue
        if key.name == "x":
            listed.append(WebKey("x/q", f"quit: {NOTHING_TO_QUIT}", ("x", "q")))
            continue
        listed.append(WebKey(key.label, key.meaning, (BROWSER.get(key.name, key.name),)))
    bound = [f"{k} {Path(f).name}" for k, f in zip("abc", files, strict=False)]
    unbound = list("abc"[len(files) :])
    note = ", ".join(bound)
    if unbound:
        verb = "is" if len(unbound) == 1 else "are"
        free = f"{', '.join(unbound)} {verb} unbound (tokenring web --action FILE, up to three)"
        note = f"{note}; {free}" if note else free
    return WebKeys(
        listed, lambda session, ring: RobotKeys.open(session, ring, files), note=note, idle_s=RENEW_POLL_S
    )


class RobotKeys:
    """The ring's one keyboard handler: an :class:`Operator` on main's PC link."""

    def __init__(self, operator: Any) -> None:
        self.operator = operator

    @classmethod
    def open(cls, session: Any, ring: str, files: list[str]) -> RobotKeys:
        from modules.pc.operator import Operator
        from tokenring.host import open_link

        return cls(Operator(open_link(session, ring), files))

    def press(self, key: str) -> dict[str, Any]:
        outcome = self.operator.press(key)
        if outcome.quit:
            return {"text": NOTHING_TO_QUIT, "ok": False}
        return {"text": outcome.text, "ok": outcome.ok}

    def idle(self) -> None:
        self.operator.keep_alive()

    def unattended(self) -> dict[str, Any] | None:
        """Nobody is there any more (the last page closed): stop what the keys hold; what was
        done, None if nothing."""
        outcome = self.operator.release()
        return None if outcome is None else {"text": outcome.text, "ok": outcome.ok}
