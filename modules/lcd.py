"""ROBLCD, the display module (seed §3.3.6, §4.3.7): menus on a 128×64 screen, a 4×4 keypad.

Keys come from the keypad hardware (``self.hw``: ``tokenring lcd`` in a terminal presses them).
Before this program runs, the LCD node's OS shows its "OS V2.0 Main Menu" on the same hardware
(:mod:`modules.display.boot_menu`); once it runs, its "Main Menu" takes over: the menus
(:mod:`modules.display.menus`) start explorations and clear the map through main,
show every module's live data decoded with protocol.yaml, and draw the map (GET_MAP to the map
module) with pan and zoom. ``lcd.data`` carries the last key, a key counter, the menu and the
selection. SHOW_TEXT puts a line of text under the menu.
"""

from __future__ import annotations

import logging
import queue
from typing import Any

from modules.display.menus import MENU_NAMES, Menus, Screen
from modules.mapping.map_request import MapCollector
from modules.units import pose_from_wire
from tokenring import UserProgram
from tokenring.runtime import current as current_runtime

log = logging.getLogger("tokenring.lcd")
REFRESH_S = 0.1


class Program(UserProgram):
    module = "lcd"

    def setup(self) -> None:
        os = self.os
        self.out = os.publish()
        os.set_own_input_id()
        self.channels = {
            spec.name: os.subscribe(spec.data.name)
            for spec in os.protocol.nodes.values()
            if spec.name != "lcd"
        }
        self.collector = MapCollector()
        self.vectors: list[tuple[int, int, int, int]] = []
        self.rt = current_runtime()  # the clock, queue and thread: the process's, or a simulation's
        self.outgoing: queue.Queue[tuple[str, str, dict[str, Any]] | None] = self.rt.queue()
        self.menus = Menus(self)
        self.screen = Screen()
        self.key_seq = 0
        self.last_key = 0
        self.started = self.rt.monotonic()
        self.sender = self.rt.spawn(self._send_loop, "lcd-send")
        self.redraw()

    # -- LcdContext -------------------------------------------------------------------------------
    def modules(self) -> list[tuple[str, int, str]]:
        live = set(self.os.membership.live) | {self.os.node_id}
        return [(spec.name, spec.id, "") for spec in self.os.protocol.nodes.values() if spec.id in live]

    def data(self, module: str) -> dict[str, Any] | None:
        if module == "lcd":
            return self.out.read()
        buffer = self.channels.get(module)
        return buffer.read() if buffer is not None and buffer.visits else None

    def send(self, target: str, command: str, **args: Any) -> None:
        self.outgoing.put((target, command, args))

    def fetch_map(self) -> None:
        self.collector.begin()
        self.send("map", "GET_MAP")

    def map_vectors(self) -> list[tuple[int, int, int, int]]:
        return self.vectors

    def pose(self) -> tuple[float, float, float] | None:
        copro = self.data("copro")
        if copro is not None and copro["pose_source"]:
            return pose_from_wire(copro["pose_x_mm"], copro["pose_y_mm"], copro["pose_angle_cdeg"])
        motor = self.data("motor")
        if motor is not None:
            return pose_from_wire(motor["x_mm"], motor["y_mm"], motor["angle_cdeg"])
        return None

    def debug(self) -> list[str]:
        stats = self.os.stats
        return [
            f"counter {self.os.counter}",
            f"visits {stats.visits}",
            f"live {','.join(str(i) for i in sorted(self.os.membership.live))}",
            f"keys {self.key_seq}",
            f"map {len(self.vectors)} vectors",
        ]

    # -- the loop ---------------------------------------------------------------------------------
    def run(self) -> None:
        next_draw = 0.0
        while self.running:
            command = self.os.receive_command(timeout=0.02)
            while command is not None:
                self.handle_command(command.name, command.args)
                command = self.os.receive_command(timeout=0)
            if self.collector.done.is_set():
                got = self.collector.wait(0)
                if got is not None:
                    self.vectors = got
                self.collector.done.clear()
            key = self.hw.key() if self.hw is not None else None
            while key is not None:
                self.press(key)
                key = self.hw.key()
            now = self.rt.monotonic()
            if now >= next_draw:
                self.redraw()
                next_draw = now + REFRESH_S

    def handle_command(self, name: str, args: dict[str, Any]) -> None:
        if self.collector.feed(name, args):
            return
        if name == "SHOW_TEXT":
            self.menus.message = str(args.get("text", ""))
        elif name == "ERROR":
            self.menus.message = f"error {args.get('error')}"

    def press(self, key: str) -> None:
        """One key from the keypad: into the menus and onto ``lcd.data``."""
        self.key_seq = (self.key_seq + 1) & 0xFF
        self.last_key = ord(key[0])
        self.menus.press(key)
        self.redraw()

    def redraw(self) -> None:
        self.menus.draw(self.screen)
        if self.hw is not None:
            self.hw.show(self.screen.to_bytes())
        self.out.write(
            key=self.last_key,
            key_seq=self.key_seq,
            menu=self.menus.menu,
            selection=self.menus.selection & 0xFF,
            stamp_ms=int((self.rt.monotonic() - self.started) * 1000) & 0xFFFFFFFF,
        )

    def _send_loop(self) -> None:
        while self.running:
            try:
                job = self.outgoing.get(timeout=0.2)
            except queue.Empty:
                continue
            if job is None:
                break
            target, command, args = job
            if not self.os.deliver(target, command, timeout=3.0, **args):
                log.warning("%s did not take %s", target, command)

    def teardown(self) -> None:
        # the display stays open: it is the node's, and its OS menu shows on it again
        self.outgoing.put(None)

    def report(self) -> dict[str, Any]:
        return {
            "menu": MENU_NAMES[self.menus.menu],
            "lines": self.menus.lines(),
            "map_vectors": len(self.vectors),
            "keys": self.key_seq,
        }
