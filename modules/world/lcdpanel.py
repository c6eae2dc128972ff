"""The LCD module's hardware: a 128×64 one-bit screen and a 4×4 keypad, on Zenoh.

The display and keypad are hardware, not the ring: the lcd program writes its framebuffer here
and reads key presses from here; ``tokenring lcd`` shows the screen in a terminal and presses
keys. Keys (all under ``tokenring/<ring>/``, see :mod:`tokenring.contract.keys`):

=====================  =======================================================================
``lcd/screen``         the screen: 1024 bytes (64 rows × 16 bytes, MSB = leftmost pixel), put
                       on every change; a queryable on the same key answers the current one
``lcd/key``            a key press: one ASCII character of ``0123456789ABCD*#``
=====================  =======================================================================
"""

from __future__ import annotations

import contextlib
import queue
import threading
from typing import Any

import zenoh

from modules.description import keys as robot_keys

SCREEN_BYTES = 1024
KEYPAD = "0123456789ABCD*#"


class LcdHardware:
    """The display and keypad as the lcd program's ``self.hw``."""

    def __init__(self, session: zenoh.Session, ring: str) -> None:
        self.session = session
        self.screen_key = robot_keys.lcd(ring, "screen")
        self.frame = bytes(SCREEN_BYTES)
        self.lock = threading.Lock()
        self.pressed: queue.Queue[str] = queue.Queue()
        self.publisher = session.declare_publisher(self.screen_key)
        self.queryable = session.declare_queryable(self.screen_key, self._on_query)
        self.subscriber = session.declare_subscriber(robot_keys.lcd(ring, "key"), self._on_key)

    def _on_query(self, query: zenoh.Query) -> None:
        with self.lock:
            frame = self.frame
        query.reply(self.screen_key, frame)

    def _on_key(self, sample: zenoh.Sample) -> None:
        text = sample.payload.to_bytes().decode("ascii", "replace").strip().upper()
        for char in text:
            if char in KEYPAD:
                self.pressed.put(char)

    def show(self, frame: bytes) -> None:
        """Put a new screen on the display (published only when it changed)."""
        if len(frame) != SCREEN_BYTES:
            raise ValueError(f"a screen is {SCREEN_BYTES} bytes, got {len(frame)}")
        with self.lock:
            if frame == self.frame:
                return
            self.frame = bytes(frame)
        self.publisher.put(frame)

    def key(self, timeout: float = 0.0) -> str | None:
        """The next key pressed, or None."""
        try:
            return self.pressed.get(timeout=timeout) if timeout > 0 else self.pressed.get_nowait()
        except queue.Empty:
            return None

    def close(self) -> None:
        for entity in (self.subscriber, self.queryable, self.publisher):
            with contextlib.suppress(zenoh.ZError):
                entity.undeclare()


def open_lcd(session: zenoh.Session, ring: str) -> Any:
    """The hardware factory ``modules.world.hardware`` registers for the lcd module."""
    return LcdHardware(session, ring)
