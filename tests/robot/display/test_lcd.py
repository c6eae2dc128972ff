"""The LCD: framebuffer, keypad and the seed's menus, walked with simulated key presses."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from modules.display.menus import (
    COMPONENT,
    COMPONENTS,
    HEIGHT,
    MAIN,
    ROBMAP,
    WIDTH,
    Menus,
    Screen,
    pack_pixels,
    render_text,
    text_rows,
    unpack_pixels,
)
from modules.pc.commands.lcd import parse_keys, render, translate_key
from tokenring.errors import UsageError


class FakeRobot:
    """An LcdContext with canned module data and a record of what the menus sent."""

    def __init__(self) -> None:
        self.sent: list[tuple[str, str, dict[str, Any]]] = []
        self.vectors: list[tuple[int, int, int, int]] = []
        self.fetches = 0
        self.robot_pose: tuple[float, float, float] | None = None

    def modules(self):
        return [("main", 10, ""), ("motor", 20, ""), ("sonar", 30, ""), ("map", 60, ""), ("lcd", 70, "")]

    def data(self, module):
        if module == "sonar":
            return {"distances": [30, 31, 255, 40, 41, 80, 29, 28], "sweep": 17, "stamp_ms": 2040}
        return None

    def send(self, target, command, **args):
        self.sent.append((target, command, args))

    def fetch_map(self):
        self.fetches += 1

    def map_vectors(self):
        return self.vectors

    def pose(self):
        return self.robot_pose

    def debug(self):
        return ["counter 5"]


def shown(menus: Menus) -> np.ndarray:
    screen = Screen()
    menus.draw(screen)
    return screen.pixels()


def assert_shows(pixels: np.ndarray, lines: list[str]) -> None:
    """Rows 1.. carry exactly these lines; row 0 is the inverted title."""
    expected = render_text(["", *lines[1:]])
    assert text_rows(pixels)[1:] == text_rows(expected)[1:]
    title = pixels[0:8]
    assert title.mean() > 0.5  # inverted: mostly lit
    assert (title == ~render_text([lines[0]])[0:8]).all()


def test_screen_packs_into_1024_bytes_and_back():
    screen = Screen()
    with screen:
        screen.text(0, "Hi")
        screen.line(0, 63, 127, 63)
    px = screen.pixels()
    assert px.shape == (HEIGHT, WIDTH)
    assert px[63].all()  # the bottom line
    frame = pack_pixels(px)
    assert len(frame) == 1024
    assert (unpack_pixels(frame) == px).all()
    with pytest.raises(ValueError, match="1024"):
        unpack_pixels(b"\0" * 10)


def test_menu_walk_with_key_presses():
    """The lcd program's menus start at its Main Menu (the OS V2.0 menu before it is the LCD
    node's OS: tests/robot/display/test_lcd_boot_menu.py)."""
    robot = FakeRobot()
    menus = Menus(robot)
    assert menus.menu == MAIN
    main_lines = [
        "Main Menu",
        "1 Explore 1",
        "2 Explore 2",
        "3 Clear Map",
        "4 Components",
        "5 Debug-Info",
        "6 Stop",
    ]
    assert_shows(shown(menus), main_lines)
    menus.press("*")  # no way back to the OS menu while the program runs
    assert menus.menu == MAIN

    menus.press("2")  # Explore 2
    assert robot.sent == [("main", "EXPLORE", {"mode": 2})]
    assert_shows(shown(menus), [*main_lines, "Explore 2 started"])
    menus.press("3")
    assert robot.sent[-1] == ("main", "CLEAR_MAP", {})

    menus.press("4")  # Components → pick sonar → its data decoded
    assert menus.menu == COMPONENTS
    menus.press("3")
    assert menus.menu == COMPONENT and menus.module == "sonar"
    assert_shows(shown(menus), ["SONAR", "distances 30,31,255,40,41,80,29,28", "sweep 17", "stamp_ms 2040"])
    menus.press("*")
    menus.press("*")
    assert menus.menu == MAIN
    menus.press("B")  # a key without meaning here changes nothing
    assert menus.menu == MAIN


def test_robmap_draws_the_map_and_pans_and_zooms():
    robot = FakeRobot()
    robot.vectors = [(0, 0, 400, 0), (400, 0, 400, 300)]  # 4 m along x, then 3 m along y (cm)
    robot.robot_pose = (2000.0, 1500.0, 0.0)
    menus = Menus(robot)
    menus.press("4")  # Components
    menus.press("4")  # ROBMAP is the 4th module in FakeRobot's list
    assert menus.menu == ROBMAP and robot.fetches == 1
    px = shown(menus)
    body = px[8:]
    rows = np.flatnonzero(body.sum(axis=1) > 60)  # the horizontal wall: one long lit row
    cols = np.flatnonzero(body.sum(axis=0) > 30)  # the vertical wall: one long lit column
    assert len(rows) >= 1 and len(cols) >= 1
    row, col = rows[-1], cols[-1]
    menus.press("6")  # pan right: the drawing moves left
    px2 = shown(menus)[8:]
    assert np.flatnonzero(px2.sum(axis=0) > 30)[-1] < col
    menus.press("5")  # fit again
    menus.press("A")  # zoom in: the map no longer fits, its long row grows past the screen
    px3 = shown(menus)[8:]
    assert not (px3 == body).all()
    menus.press("#")
    assert robot.fetches == 2
    assert row > 0


def test_terminal_rendering_and_key_mapping():
    screen = Screen()
    with screen:
        screen.line(0, 0, 127, 0)
        screen.line(0, 3, 127, 3)
    text = render(screen.to_bytes())
    lines = text.splitlines()
    assert len(lines) == 32 + 2
    assert lines[1] == "|" + "▀" * 128 + "|"
    assert lines[2] == "|" + "▄" * 128 + "|"
    assert [translate_key(c) for c in "5a*#\r+-q"] == ["5", "A", "*", "#", "#", "A", "B", "quit"]
    assert translate_key("\x1b") == "*"
    assert parse_keys("1 2, a#") == ["1", "2", "A", "#"]
    with pytest.raises(UsageError, match="not on the keypad"):
        parse_keys("1x")
