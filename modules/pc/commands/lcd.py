"""``tokenring lcd``: the LCD's screen in a terminal (Unicode half-blocks) and its keypad on the keyboard.

Keys: 0-9, a-d, * and # as on the keypad; Esc = * (leave a menu), Enter = #; arrows = 2/4/6/8
(pan the map); + and - = A and B (zoom); q quits. ``--keys "1 2"`` presses keys without a
terminal; ``--png FILE`` saves the current screen; ``--once`` prints it once.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import time
from typing import TYPE_CHECKING, Any

from tokenring import TransportError, UsageError
from tokenring.cli import non_negative_seconds

if TYPE_CHECKING:
    from pathlib import Path

HELP = "show the LCD screen in the terminal and type on its keypad"

EXAMPLES = """examples:
  tokenring lcd                               # the live screen; the keyboard is the keypad
  tokenring lcd --keys 2                      # the boot menu's Components, printed once
  tokenring lcd --png screen.png --scale 6    # the screen as a picture
"""

KEYPAD = "0123456789ABCD*#"
ARROWS = {"A": "2", "B": "8", "C": "6", "D": "4"}  # ESC [ A = up -> pan up (2) ...


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli import add_ring_options, with_examples

    p = sub.add_parser(
        "lcd",
        **with_examples(EXAMPLES),
        help=HELP,
        description="Open the robot's 128x64 LCD in the terminal (half-block pixels) and map the keyboard "
        "to its 4x4 keypad: 0-9 a-d * #, Esc = *, Enter = #, arrows pan, + - zoom, q quits.",
    )
    p.add_argument("--png", metavar="FILE", help="save the current screen as a PNG and exit")
    p.add_argument("--scale", type=int, default=4, help="PNG pixels per LCD pixel (default %(default)s)")
    p.add_argument(
        "--keys", metavar="KEYS", help='press these keypad keys (e.g. "1 2"), print the screen, exit'
    )
    p.add_argument(
        "--delay",
        type=non_negative_seconds,
        default=0.3,
        help="seconds between --keys presses (default %(default)s)",
    )
    p.add_argument("--once", action="store_true", help="print the screen once and exit")
    add_ring_options(p, listen=False)


def render(frame: bytes) -> str:
    """The screen as 32 lines of 128 half-block characters."""
    from modules.display.menus import unpack_pixels

    px = unpack_pixels(frame)
    chars = {(False, False): " ", (True, False): "▀", (False, True): "▄", (True, True): "█"}
    rows = []
    for r in range(0, px.shape[0], 2):
        top, bottom = px[r], px[r + 1]
        rows.append("".join(chars[(bool(a), bool(b))] for a, b in zip(top, bottom, strict=True)))
    border = "+" + "-" * px.shape[1] + "+"
    return "\n".join([border, *(f"|{row}|" for row in rows), border])


def fetch_screen(session: Any, ring: str, timeout: float = 3.0) -> bytes:
    """The current screen; retried while a freshly opened session has not found the LCD yet."""
    from modules.description import keys as robot_keys

    deadline = time.monotonic() + timeout
    while True:
        for reply in session.get(robot_keys.lcd(ring, "screen"), timeout=1.0):
            if reply.ok is not None:
                return reply.ok.payload.to_bytes()
        if time.monotonic() > deadline:
            raise TransportError(f"no LCD answered on ring {ring!r} (is the lcd node up?)")
        time.sleep(0.1)


def save_png(frame: bytes, path: str | Path, scale: int = 4) -> None:
    """The screen as a PNG: lit pixels dark on the LCD's pale green, ``scale`` px per pixel."""
    from PIL import Image

    from modules.display.menus import unpack_pixels

    px = unpack_pixels(frame)
    image = Image.new("RGB", (px.shape[1], px.shape[0]), (170, 200, 150))
    lit = Image.fromarray(px.astype("uint8") * 255, mode="L")
    image.paste((20, 30, 20), mask=lit)
    image = image.resize((px.shape[1] * scale, px.shape[0] * scale), Image.NEAREST)
    try:
        image.save(path, format="PNG")
    except OSError as exc:
        raise UsageError(f"--png {path}: cannot write: {exc.strerror or exc}") from None


def parse_keys(text: str) -> list[str]:
    pressed = [k.upper() for k in text if not k.isspace() and k != ","]
    bad = [k for k in pressed if k not in KEYPAD]
    if bad:
        raise UsageError(f"--keys: {''.join(bad)!r} is not on the keypad (keys: {KEYPAD})")
    return pressed


def run(args: argparse.Namespace) -> int:
    from modules.description import keys as robot_keys
    from tokenring import keys
    from tokenring.cli import tap_session

    if args.scale < 1 or args.scale > 32:
        raise UsageError("--scale must be 1..32")
    pressed = parse_keys(args.keys) if args.keys else []
    ring = keys.check_ring_name(args.ring)
    with tap_session(args) as session:
        key_pub = session.declare_publisher(robot_keys.lcd(ring, "key"))
        fetch_screen(session, ring)  # fail early with a clear message if no LCD is there
        if pressed:
            for key in pressed:
                key_pub.put(key.encode())
                time.sleep(args.delay)
        if args.png:
            time.sleep(0.2 if pressed else 0)
            save_png(fetch_screen(session, ring), args.png, args.scale)
            print(f"saved the LCD screen to {args.png}")
            return 0
        if pressed or args.once or not sys.stdin.isatty():
            print(render(fetch_screen(session, ring)))
            return 0
        return interactive(session, ring, key_pub)


def interactive(session: Any, ring: str, key_pub: Any) -> int:
    """Live view: redraw on every new screen, keyboard → keypad, until q or Ctrl-C."""
    import select
    import termios
    import threading
    import tty

    from modules.description import keys as robot_keys

    latest = {"frame": fetch_screen(session, ring)}
    changed = threading.Event()
    changed.set()

    def on_screen(sample: Any) -> None:
        latest["frame"] = sample.payload.to_bytes()
        changed.set()

    subscriber = session.declare_subscriber(robot_keys.lcd(ring, "screen"), on_screen)
    fd = sys.stdin.fileno()
    saved = termios.tcgetattr(fd)
    out = sys.stdout
    try:
        tty.setcbreak(fd)
        out.write("\x1b[2J\x1b[?25l")
        while True:
            if changed.is_set():
                changed.clear()
                out.write(
                    "\x1b[H"
                    + render(latest["frame"])
                    + "\nkeys: 0-9 a-d * # | Esc=* Enter=# arrows=pan +/-=zoom q=quit\n"
                )
                out.flush()
            ready, _, _ = select.select([fd], [], [], 0.05)
            if not ready:
                continue
            char = os.read(fd, 1).decode("latin-1")
            key = translate_key(char, fd)
            if key == "quit":
                break
            if key:
                key_pub.put(key.encode())
    except KeyboardInterrupt:
        pass
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)
        out.write("\x1b[?25h\n")
        with contextlib.suppress(Exception):
            subscriber.undeclare()
    return 0


def translate_key(char: str, fd: int | None = None) -> str | None:
    """A keyboard character (and an escape sequence after it) → a keypad key, "quit" or None."""
    if char in ("q", "Q"):
        return "quit"
    if char == "\x1b":
        import select

        if fd is not None and select.select([fd], [], [], 0.02)[0]:
            rest = os.read(fd, 2).decode("latin-1")
            if len(rest) == 2 and rest[0] == "[" and rest[1] in ARROWS:
                return ARROWS[rest[1]]
        return "*"
    if char in ("\r", "\n"):
        return "#"
    if char == "+":
        return "A"
    if char == "-":
        return "B"
    upper = char.upper()
    return upper if upper in KEYPAD else None
