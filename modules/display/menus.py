"""The LCD's screen and menus (seed §3.3.6, §4.3.7): a 128×64 one-bit display and a 4×4 keypad.

The framebuffer is a luma.core ``dummy`` device (a real small-display library: mode "1",
bitmap fonts); :class:`Screen` packs it into the 1024 bytes the display hardware takes.

Keys: ``0``–``9``, ``A``–``D``, ``*`` (Escape: leave a menu) and ``#`` (Enter/refresh).
Menus as in the seed's figure 4.8. After power-on the LCD node's OS shows :class:`OsMenu`,
"OS V2.0 Main Menu" (1 Start Robbi: ARCNET_START_SYSTEM; 2 Components: every node's name, ID and
program date), before any program runs (:mod:`modules.display.boot_menu`). Once the programs run, the
lcd program shows :class:`Menus`, "Main Menu" (1 Explore 1, 2 Explore 2, 3 Clear Map,
4 Components, 5 Debug-Info; ours: 6 Stop). Its Components lists the modules; picking one shows its
live data decoded with protocol.yaml (2/8 scroll); ROBMAP shows the map: 2/4/6/8 pan, A zoom in,
B zoom out, 5 fit, # fetch the map again.

The menus hold no I/O: they draw from and act through a :class:`LcdContext` (the OS menu: an
:class:`OsContext`), so a test can walk them with simulated key presses and assert the framebuffer.
"""

from __future__ import annotations

import math
import time
from typing import Any, Protocol

import numpy as np
from luma.core.device import dummy
from luma.core.legacy import text as legacy_text
from luma.core.legacy.font import LCD_FONT, proportional
from luma.core.render import canvas

WIDTH, HEIGHT = 128, 64
LINE_HEIGHT = 8
LINES = HEIGHT // LINE_HEIGHT
KEYS = "0123456789ABCD*#"
ESCAPE, ENTER = "*", "#"
FONT = proportional(LCD_FONT)


class Screen:
    """The 128×64 one-bit framebuffer."""

    def __init__(self) -> None:
        self.device = dummy(width=WIDTH, height=HEIGHT, mode="1")
        self._draw: Any = None
        self._canvas: Any = None

    def __enter__(self) -> Screen:
        self._canvas = canvas(self.device)
        self._draw = self._canvas.__enter__()
        return self

    def __exit__(self, *exc: Any) -> None:
        self._canvas.__exit__(*exc)
        self._draw = self._canvas = None

    def text(self, row: int, value: str, x: int = 0, invert: bool = False) -> None:
        """One line of text on text row ``row`` (0..7)."""
        y = row * LINE_HEIGHT
        if invert:
            self._draw.rectangle((0, y, WIDTH - 1, y + LINE_HEIGHT - 1), fill="white")
        legacy_text(self._draw, (x, y), value, fill="black" if invert else "white", font=FONT)

    def line(self, x1: float, y1: float, x2: float, y2: float) -> None:
        self._draw.line((round(x1), round(y1), round(x2), round(y2)), fill="white")

    def rect(self, x1: int, y1: int, x2: int, y2: int, fill: bool = False) -> None:
        self._draw.rectangle((x1, y1, x2, y2), outline="white", fill="white" if fill else None)

    def pixels(self) -> np.ndarray:
        """The screen as a (64, 128) bool array, True = pixel on."""
        return np.array(self.device.image.convert("1"), dtype=bool)

    def to_bytes(self) -> bytes:
        """1024 bytes: 64 rows of 16 bytes, most significant bit leftmost."""
        return pack_pixels(self.pixels())


def pack_pixels(pixels: np.ndarray) -> bytes:
    return np.packbits(pixels.astype(np.uint8), axis=1).tobytes()


def unpack_pixels(frame: bytes) -> np.ndarray:
    """The inverse of :func:`pack_pixels`: a (64, 128) bool array."""
    if len(frame) != WIDTH * HEIGHT // 8:
        raise ValueError(f"a screen is {WIDTH * HEIGHT // 8} bytes, got {len(frame)}")
    rows = np.frombuffer(frame, dtype=np.uint8).reshape(HEIGHT, WIDTH // 8)
    return np.unpackbits(rows, axis=1).astype(bool)


def text_rows(pixels: np.ndarray) -> list[bytes]:
    """Each text row's pixels as bytes: a cheap fingerprint for comparing rendered text."""
    return [pixels[r * LINE_HEIGHT : (r + 1) * LINE_HEIGHT].tobytes() for r in range(LINES)]


def render_text(lines: list[str]) -> np.ndarray:
    """What :class:`Screen` shows for these lines (tests compare menus against it)."""
    screen = Screen()
    with screen:
        for row, value in enumerate(lines[:LINES]):
            screen.text(row, value)
    return screen.pixels()


class LcdContext(Protocol):
    """What the menus need from the LCD module."""

    def modules(self) -> list[tuple[str, int, str]]:
        """Active modules: (name, ID, program date or '')."""

    def data(self, module: str) -> dict[str, Any] | None:
        """A module's latest data channel, decoded (None if not seen)."""

    def send(self, target: str, command: str, **args: Any) -> None:
        """Send a command over the ring."""

    def fetch_map(self) -> None:
        """Start a GET_MAP; :meth:`map_vectors` has the answer when it arrived."""

    def map_vectors(self) -> list[tuple[int, int, int, int]]:
        """The last map received, vectors in cm."""

    def pose(self) -> tuple[float, float, float] | None:
        """The robot's best pose (mm, mm, rad CCW), if known."""

    def debug(self) -> list[str]:
        """Lines for Debug-Info."""


#: the menus' numbers (``lcd.data``'s ``menu``): BOOT and OS_COMPONENTS are the OS's (:class:`OsMenu`)
BOOT, MAIN, OS_COMPONENTS, COMPONENTS, COMPONENT, ROBMAP, DEBUG = range(7)
MENU_NAMES = ["boot", "main", "os-components", "components", "component", "robmap", "debug"]


class OsContext(Protocol):
    """What the OS menu needs from the LCD node's OS."""

    def start_system(self) -> str:
        """Broadcast ARCNET_START_SYSTEM over the ring; a line saying what happened."""

    def scan_components(self) -> list[tuple[str, int, int]] | None:
        """Every node on the ring as (name, ID, program time stamp in ms since 1970, 0 = no
        program), from ARCNET_SCAN and ARCNET_GET_CONFIG; None if the scan got no answer."""


def program_date(stamp_ms: int) -> str:
    """A program's date as the OS menu shows it, ``DD.MM.YYYY`` local time (the seed's date
    format; a time of day would not fit beside the longer names), ``-`` for no program."""
    if not stamp_ms:
        return "-"
    return time.strftime("%d.%m.%Y", time.localtime(stamp_ms / 1000))


def component_row(name: str, node_id: int, stamp_ms: int) -> str:
    """One node in the OS menu's Components: name, ID and program date."""
    return f"{name.upper()} {node_id} {program_date(stamp_ms)}"


class OsMenu:
    """The LCD node's own menu from power-on until the programs run (seed §4.3.7, figure 4.8):
    1 Start Robbi broadcasts ARCNET_START_SYSTEM; 2 Components scans the ring and lists every
    node with name, ID and program date (2/8 scroll, # scans again, * back)."""

    def __init__(self, context: OsContext) -> None:
        self.ctx = context
        self.menu = BOOT
        self.scroll = 0
        self.message = ""
        self.components: list[tuple[str, int, int]] | None = []

    def press(self, key: str) -> None:
        key = key.upper()
        if key not in KEYS:
            return
        if self.menu == BOOT:
            if key == "1":
                self.message = self.ctx.start_system()
            elif key == "2":
                self.menu, self.scroll, self.message = OS_COMPONENTS, 0, ""
                self.components = self.ctx.scan_components()
        elif key == ESCAPE:
            self.menu = BOOT
        elif key == ENTER:
            self.components = self.ctx.scan_components()
        elif key == "8":
            self.scroll += 1
        elif key == "2":
            self.scroll = max(0, self.scroll - 1)

    def lines(self) -> list[str]:
        """The menu's text lines (what :meth:`draw` writes)."""
        if self.menu == BOOT:
            out = ["OS V2.0 Main Menu", "1 Start Robbi", "2 Components"]
            return [*out, self.message] if self.message else out
        if self.components is None:
            rows = ["no answer (# again)"]
        else:
            rows = [component_row(*component) for component in self.components] or ["no nodes"]
        size = LINES - 1
        self.scroll = min(self.scroll, max(0, len(rows) - size))
        return ["Components", *rows[self.scroll : self.scroll + size]]

    def draw(self, screen: Screen) -> None:
        with screen:
            for row, value in enumerate(self.lines()[:LINES]):
                screen.text(row, value, invert=(row == 0))


class Menus:
    """The lcd program's menus, from its Main Menu on: :meth:`press` a key, :meth:`draw` the
    current screen."""

    def __init__(self, context: LcdContext) -> None:
        self.ctx = context
        self.menu = MAIN
        self.stack: list[int] = []
        self.selection = 0
        self.scroll = 0
        self.module = ""
        self.message = ""
        self.view_center = (0.0, 0.0)
        self.view_mm_per_px = 50.0  # 1 px = 5 cm: the 128 px wide screen shows 6.4 m
        self.fitted = False

    # -- keys ---------------------------------------------------------------------------------
    def press(self, key: str) -> None:
        key = key.upper()
        if key not in KEYS:
            return
        self.message = ""
        if key == ESCAPE:
            if self.stack:
                self.menu = self.stack.pop()
                self.scroll = 0
            return
        handler = {
            MAIN: self._main,
            COMPONENTS: self._components,
            COMPONENT: self._scroll_keys,
            ROBMAP: self._robmap,
            DEBUG: self._scroll_keys,
        }[self.menu]
        handler(key)

    def _enter(self, menu: int) -> None:
        self.stack.append(self.menu)
        self.menu = menu
        self.scroll = 0

    def _main(self, key: str) -> None:
        if key in ("1", "2"):
            self.ctx.send("main", "EXPLORE", mode=int(key))
            self.message = f"Explore {key} started"
            self.selection = int(key)
        elif key == "3":
            self.ctx.send("main", "CLEAR_MAP")
            self.message = "Map cleared"
            self.selection = 3
        elif key == "4":
            self._enter(COMPONENTS)
        elif key == "5":
            self._enter(DEBUG)
        elif key == "6":
            self.ctx.send("main", "STOP_EXPLORE")
            self.message = "Stopped"
            self.selection = 6

    def _components(self, key: str) -> None:
        names = [m[0] for m in self.ctx.modules()]
        if key.isdigit() and 1 <= int(key) <= len(names):
            self.module = names[int(key) - 1]
            self.selection = int(key)
            if self.module == "map":
                self._enter(ROBMAP)
                self.fitted = False
                self.ctx.fetch_map()
            else:
                self._enter(COMPONENT)

    def _scroll_keys(self, key: str) -> None:
        if key == "8":
            self.scroll += 1
        elif key == "2":
            self.scroll = max(0, self.scroll - 1)

    def _robmap(self, key: str) -> None:
        cx, cy = self.view_center
        step = self.view_mm_per_px * 16
        if key == "2":
            self.view_center = (cx, cy + step)
        elif key == "8":
            self.view_center = (cx, cy - step)
        elif key == "4":
            self.view_center = (cx - step, cy)
        elif key == "6":
            self.view_center = (cx + step, cy)
        elif key == "A":
            self.view_mm_per_px = max(5.0, self.view_mm_per_px / 1.5)
        elif key == "B":
            self.view_mm_per_px = min(2000.0, self.view_mm_per_px * 1.5)
        elif key == "5":
            self.fit()
        elif key == ENTER:
            self.ctx.fetch_map()
            self.fitted = False

    def fit(self) -> None:
        """Centre and scale the view on the map (and the robot)."""
        pts = [(v[0] * 10.0, v[1] * 10.0) for v in self.ctx.map_vectors()]
        pts += [(v[2] * 10.0, v[3] * 10.0) for v in self.ctx.map_vectors()]
        pose = self.ctx.pose()
        if pose is not None:
            pts.append(pose[:2])
        if not pts:
            return
        xs, ys = [p[0] for p in pts], [p[1] for p in pts]
        self.view_center = ((min(xs) + max(xs)) / 2, (min(ys) + max(ys)) / 2)
        span = max((max(xs) - min(xs)) / (WIDTH - 8), (max(ys) - min(ys)) / (HEIGHT - 12), 5.0)
        self.view_mm_per_px = span
        self.fitted = True

    # -- drawing ------------------------------------------------------------------------------
    def draw(self, screen: Screen) -> None:
        with screen:
            {
                MAIN: self._draw_main,
                COMPONENTS: self._draw_modules,
                COMPONENT: self._draw_component,
                ROBMAP: self._draw_map,
                DEBUG: self._draw_debug,
            }[self.menu](screen)

    def lines(self) -> list[str]:
        """The text lines of a text menu (what :meth:`draw` writes), for tests and the terminal."""
        if self.menu == MAIN:
            out = [
                "Main Menu",
                "1 Explore 1",
                "2 Explore 2",
                "3 Clear Map",
                "4 Components",
                "5 Debug-Info",
                "6 Stop",
            ]
            return [*out, self.message] if self.message else out
        if self.menu == COMPONENTS:
            rows = [
                f"{i + 1} {name.upper()} {node_id}{' ' + date if date else ''}"
                for i, (name, node_id, date) in enumerate(self.ctx.modules())
            ]
            return ["Components", *self._page(rows, LINES - 1)]
        if self.menu == COMPONENT:
            data = self.ctx.data(self.module)
            rows = ["no data yet"] if data is None else [f"{k} {_short(v)}" for k, v in data.items()]
            return [self.module.upper(), *self._page(rows, LINES - 1)]
        if self.menu == DEBUG:
            return ["Debug-Info", *self._page(self.ctx.debug(), LINES - 1)]
        return []

    def _page(self, rows: list[str], size: int) -> list[str]:
        self.scroll = min(self.scroll, max(0, len(rows) - size))
        return rows[self.scroll : self.scroll + size]

    def _draw_text_menu(self, screen: Screen) -> None:
        for row, value in enumerate(self.lines()[:LINES]):
            screen.text(row, value, invert=(row == 0))

    _draw_main = _draw_modules = _draw_component = _draw_debug = _draw_text_menu

    def _draw_map(self, screen: Screen) -> None:
        vectors = self.ctx.map_vectors()
        if not self.fitted and vectors:
            self.fit()
        scale = self.view_mm_per_px
        cx, cy = self.view_center

        def px(x_mm: float, y_mm: float) -> tuple[float, float]:
            return (WIDTH / 2 + (x_mm - cx) / scale, (HEIGHT + 8) / 2 - (y_mm - cy) / scale)

        for x1, y1, x2, y2 in vectors:
            a, b = px(x1 * 10.0, y1 * 10.0), px(x2 * 10.0, y2 * 10.0)
            if _visible(a, b):
                screen.line(*a, *b)
        pose = self.ctx.pose()
        if pose is not None:
            x, y = px(pose[0], pose[1])
            if -4 <= x <= WIDTH + 4 and 8 <= y <= HEIGHT + 4:
                screen.rect(round(x) - 1, round(y) - 1, round(x) + 1, round(y) + 1, fill=True)
                hx, hy = x + 5 * math.cos(pose[2]), y - 5 * math.sin(pose[2])
                screen.line(x, y, hx, hy)
        screen.rect(0, 0, WIDTH - 1, 7, fill=True)
        scale_m = scale * WIDTH / 1000.0
        screen.text(0, f"ROBMAP {len(vectors)}v {scale_m:.1f}m", invert=True)


def _visible(a: tuple[float, float], b: tuple[float, float]) -> bool:
    return not (
        (a[0] < 0 and b[0] < 0)
        or (a[0] > WIDTH and b[0] > WIDTH)
        or (a[1] < 8 and b[1] < 8)
        or (a[1] > HEIGHT and b[1] > HEIGHT)
    )


def _short(value: Any) -> str:
    if isinstance(value, list):
        return ",".join(str(v) for v in value)
    if isinstance(value, float):
        return f"{value:.1f}"
    return str(value)
