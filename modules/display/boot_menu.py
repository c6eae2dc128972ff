"""The LCD node's OS layer (seed 001 §4.3.7, figure 4.8): its "OS V2.0 Main Menu" from power-on
until the programs run.

On the seed robot this menu belonged to the LCD node's operating system, not to a program: it was
there before anything was downloaded, "1 Start Robbi" started every node's program
(ARCNET_START_SYSTEM), "2 Components" listed every node on the network with name, ID and the date
of its software. Here the robot plugs it into the LCD node as a resident program
(:mod:`tokenring.node.resident`, registered by :mod:`modules.plugin`): it draws
:class:`~modules.display.menus.OsMenu` on the display and reads the keypad (``self.hw``, the same
hardware the lcd program gets) while no program runs, and leaves both to the lcd program once it
runs, whose own "Main Menu" takes over.
"""

from __future__ import annotations

import logging
from typing import Any

from modules.display.menus import BOOT, MENU_NAMES, OsMenu, Screen, program_date
from tokenring import ResidentProgram, TokenRingError

log = logging.getLogger("tokenring.lcd")
KEY_POLL_S = 0.05  # how often the keypad is read while the menu is shown
IDLE_POLL_S = 0.2  # how often a running program is checked for having stopped


class LcdOs(ResidentProgram):
    """The OS V2.0 menu on the LCD node: shown whenever no program runs there."""

    def setup(self) -> None:
        self.menu = OsMenu(self)
        self.screen = Screen()
        self.presses = 0
        self.showing = False  # the menu is on the display (no program has it)
        self.scanned: list[dict[str, Any]] = []

    def run(self) -> None:
        if self.hw is None:  # no display here: nothing to show, nothing to press
            return
        while self.running:
            if self.program_running:  # the lcd program has the display and the keypad
                if self.showing:  # when it stops, the OS is back at its main menu
                    self.showing = False
                    self.menu.menu, self.menu.message = BOOT, ""
                self.wait(IDLE_POLL_S)
                continue
            if not self.showing:
                self.showing = True
                self.redraw()
            key = self.hw.key()
            if key is None:
                self.wait(KEY_POLL_S)
                continue
            self.presses += 1
            self.menu.press(key)
            if not self.program_running:
                self.redraw()

    def redraw(self) -> None:
        self.menu.draw(self.screen)
        self.hw.show(self.screen.to_bytes())

    # -- OsContext ------------------------------------------------------------------------------
    def start_system(self) -> str:
        """1 Start Robbi: ARCNET_START_SYSTEM from this node; the line the menu shows after it."""
        try:
            took = self.broadcast_start_system()
        except TokenRingError as exc:
            log.warning("Start Robbi: %s", exc)
            return "start failed"
        log.info("Start Robbi: ARCNET_START_SYSTEM taken by %s", took)
        # a node takes it only if it has a program to start
        return f"starting {len(took)} programs" if took else "no program to start"

    def scan_components(self) -> list[tuple[str, int, int]] | None:
        """2 Components: every node's name, ID and program time stamp, scanned over the ring."""
        try:
            self.scanned = self.scan_programs()
        except TokenRingError as exc:
            log.warning("Components: %s", exc)
            return None
        return [(c["name"], c["id"], c["stamp_ms"]) for c in self.scanned]

    def report(self) -> dict[str, Any]:
        """The menu, its lines, whether it is on the display, and the last scan's nodes."""
        return {
            "menu": MENU_NAMES[self.menu.menu],
            "lines": self.menu.lines(),
            "showing": self.showing,
            "keys": self.presses,
            "components": [
                {
                    "name": c["name"],
                    "id": c["id"],
                    "state": c["state"],
                    "stamp_ms": c["stamp_ms"],
                    "date": program_date(c["stamp_ms"]),
                }
                for c in self.scanned
            ],
        }
