"""The LCD node's "OS V2.0 Main Menu" before the programs start (seed 001 §4.3.7, figure 4.8), and
``tokenring up --no-start``, which boots, downloads and waits at that menu.

The seed: "Nach Einschalten des Systems meldet sich zunächst das Betriebssystem (OS V2.0 Main
Menu) ... Start Robbi ... Components: alle aktiven Rechner nacheinander mit ihrem Namen, ID und
Datum der Software ... Bei 'Start Robbi' werden nun alle User-Programme aktiviert."

The screens expected here are drawn by this file itself with the display library (8-pixel text
rows, LCD font, an inverted title row) and compared with what ``tokenring lcd`` prints.
"""

from __future__ import annotations

import json
import os
import queue
import shlex
import shutil
import signal
import subprocess
import sys
import time
from typing import Any

import numpy as np
import pytest
from luma.core.device import dummy
from luma.core.legacy import text, textsize
from luma.core.legacy.font import LCD_FONT, proportional
from luma.core.render import canvas

from modules.display.boot_menu import LcdOs
from modules.display.menus import OsMenu, Screen
from modules.pc.feed import LcdSource
from tests.support.processes import REPO, run_tokenring
from tests.support.ringutil import control, launcher_pids, tap, wait_until
from tokenring.contract.protocol import default_protocol
from tokenring.node.resident import ResidentHost
from tokenring.node.system.vocabulary import State

FONT = proportional(LCD_FONT)
OS_MENU = ["OS V2.0 Main Menu", "1 Start Robbi", "2 Components"]
MAIN_MENU = [
    "Main Menu",
    "1 Explore 1",
    "2 Explore 2",
    "3 Clear Map",
    "4 Components",
    "5 Debug-Info",
    "6 Stop",
]
HALF_BLOCKS = {" ": (False, False), "▀": (True, False), "▄": (False, True), "█": (True, True)}


def local_ms(year: int, month: int, day: int, hour: int, minute: int) -> int:
    """A local time as ms since 1970 (what a program file's time stamp is)."""
    return int(time.mktime((year, month, day, hour, minute, 0, 0, 0, -1)) * 1000)


# the seed robot's year: each program file gets a time stamp of its own
STAMPS = {
    "main": local_ms(2001, 6, 15, 14, 30),
    "map": local_ms(2001, 7, 2, 9, 5),
    "lcd": local_ms(2001, 8, 20, 17, 45),
}
COMPONENTS = ["Components", "MAIN 10 15.06.2001", "MAP 60 02.07.2001", "LCD 70 20.08.2001"]


def expected_screen(lines: list[str]) -> np.ndarray:
    """The 128×64 screen of a text menu: the title inverted on row 0, a line per 8-pixel row."""
    device = dummy(width=128, height=64, mode="1")
    with canvas(device) as draw:
        draw.rectangle((0, 0, 127, 7), fill="white")
        text(draw, (0, 0), lines[0], fill="black", font=FONT)
        for row, line in enumerate(lines[1:8], start=1):
            text(draw, (0, 8 * row), line, fill="white", font=FONT)
    return np.array(device.image.convert("1"), dtype=bool)


def unpack(frame: bytes) -> np.ndarray:
    """A display frame (64 rows of 16 bytes, MSB leftmost) as pixels."""
    rows = np.frombuffer(frame, dtype=np.uint8).reshape(64, 16)
    return np.unpackbits(rows, axis=1).astype(bool)


def from_terminal(printed: str) -> np.ndarray:
    """The pixels of ``tokenring lcd``'s half-block picture (two pixel rows per character row)."""
    rows = [line[1:-1] for line in printed.splitlines() if line.startswith("|") and line.endswith("|")]
    assert len(rows) == 32 and all(len(row) == 128 for row in rows), printed
    pixels = np.zeros((64, 128), dtype=bool)
    for r, row in enumerate(rows):
        for c, char in enumerate(row):
            pixels[2 * r, c], pixels[2 * r + 1, c] = HALF_BLOCKS[char]
    return pixels


# -- the menu alone -------------------------------------------------------------------------------


class FakeNodeOs:
    """The LCD node's OS as the menu sees it: a start that is recorded, a scan that is canned."""

    def __init__(self, nodes: list[tuple[str, int, int]] | None) -> None:
        self.nodes = nodes
        self.starts = 0
        self.scans = 0

    def start_system(self) -> str:
        self.starts += 1
        return "starting 3 programs"

    def scan_components(self) -> list[tuple[str, int, int]] | None:
        self.scans += 1
        return self.nodes


def drawn(menu: OsMenu) -> np.ndarray:
    screen = Screen()
    menu.draw(screen)
    return unpack(screen.to_bytes())


def test_os_menu_draws_starts_the_system_and_lists_program_dates():
    eight = [
        ("main", 10, STAMPS["main"]),
        ("motor", 20, STAMPS["map"]),
        ("sonar", 30, STAMPS["lcd"]),
        ("compass", 40, STAMPS["main"]),
        ("copro", 50, STAMPS["main"]),
        ("map", 60, STAMPS["map"]),
        ("lcd", 70, STAMPS["lcd"]),
        ("charger", 80, 0),  # a node without a program
    ]
    node_os = FakeNodeOs(eight)
    menu = OsMenu(node_os)
    assert (drawn(menu) == expected_screen(OS_MENU)).all()

    menu.press("2")  # Components: the ring is scanned, every node with name, ID, program date
    assert node_os.scans == 1
    rows = [
        "MAIN 10 15.06.2001",
        "MOTOR 20 02.07.2001",
        "SONAR 30 20.08.2001",
        "COMPASS 40 15.06.2001",
        "COPRO 50 15.06.2001",
        "MAP 60 02.07.2001",
        "LCD 70 20.08.2001",
        "CHARGER 80 -",
    ]
    assert all(textsize(row, FONT)[0] <= 128 for row in rows)  # each fits the screen's width
    assert (drawn(menu) == expected_screen(["Components", *rows[:7]])).all()
    menu.press("8")  # scroll: the eighth node comes into view
    assert (drawn(menu) == expected_screen(["Components", *rows[1:8]])).all()
    menu.press("#")  # scan again
    assert node_os.scans == 2 and node_os.starts == 0
    menu.press("*")  # Escape: back at the OS menu
    assert (drawn(menu) == expected_screen(OS_MENU)).all()

    menu.press("1")  # Start Robbi: ARCNET_START_SYSTEM, and a line saying so
    assert node_os.starts == 1
    assert (drawn(menu) == expected_screen([*OS_MENU, "starting 3 programs"])).all()


def test_a_scan_without_answer_says_so():
    menu = OsMenu(FakeNodeOs(None))
    menu.press("2")
    assert (drawn(menu) == expected_screen(["Components", "no answer (# again)"])).all()


# -- the resident on the node, with the hardware and the system layer stood in for -----------------


class FakeKeypadDisplay:
    """The LCD hardware: keys pressed into a queue, every frame shown kept."""

    def __init__(self) -> None:
        self.keys: queue.Queue[str] = queue.Queue()
        self.frames: list[bytes] = []

    def key(self, timeout: float = 0.0) -> str | None:
        try:
            return self.keys.get_nowait()
        except queue.Empty:
            return None

    def show(self, frame: bytes) -> None:
        self.frames.append(bytes(frame))

    def showing(self, lines: list[str]) -> bool:
        return bool(self.frames) and bool((unpack(self.frames[-1]) == expected_screen(lines)).all())


class FakeSystemLayer:
    """ARCNET_START_SYSTEM, ARCNET_SCAN and ARCNET_GET_CONFIG as the node's system layer answers."""

    START_SYSTEM = 0x33

    def __init__(self) -> None:
        self.state = State.STOPPED
        self.broadcasts: list[int] = []

    def program_state(self) -> State:
        return self.state

    def broadcast(self, code: int, what: str, timeout: float) -> list[int]:
        self.broadcasts.append(code)
        return [10, 70]

    def scan(self, timeout: float) -> list[int]:
        return [10, 70]

    def configs(self, ids: list[int], timeout: float) -> dict[int, dict[str, Any]]:
        names = {10: "main", 70: "lcd"}
        return {i: {"id": i, "name": names[i], "state": "STOPPED", "stamp_ms": STAMPS[names[i]]} for i in ids}


class FakeOs:
    name = "lcd"
    stopping = False


def test_the_resident_shows_its_menu_until_a_program_runs_and_again_when_it_stops():
    display, system = FakeKeypadDisplay(), FakeSystemLayer()
    host = ResidentHost(LcdOs, FakeOs(), system, display)  # type: ignore[arg-type]
    host.start()
    try:
        wait_until(lambda: display.showing(OS_MENU), 30, "the OS menu on the display")
        display.keys.put("2")
        wait_until(
            lambda: display.showing(["Components", "MAIN 10 15.06.2001", "LCD 70 20.08.2001"]),
            30,
            "Components with the program dates",
        )
        display.keys.put("*")
        display.keys.put("1")
        wait_until(lambda: system.broadcasts == [system.START_SYSTEM], 30, "ARCNET_START_SYSTEM")
        system.state = State.RUNNING  # the lcd program runs: it has the display now
        wait_until(lambda: not host.control({})["report"]["showing"], 30, "the menu to step aside")
        frames = len(display.frames)
        system.state = State.STOPPED  # stopped (load --stop): the OS menu is back, without the old line
        wait_until(lambda: len(display.frames) > frames and display.showing(OS_MENU), 30, "the OS menu again")
        report = host.control({})
        assert report["error"] is None and report["report"]["menu"] == "boot"
        assert [c["date"] for c in report["report"]["components"]] == ["15.06.2001", "20.08.2001"]
    finally:
        host.stop()
    assert not host.control({})["alive"]


# -- tokenring up --no-start on a real ring ----------------------------------------------------------


def tokenring_lcd(ring: str, endpoint: str, *args: str) -> str:
    """``tokenring lcd`` as a user runs it; its printed screen."""
    out = run_tokenring("lcd", "--ring", ring, "-e", endpoint, *args, timeout=60)
    assert out.returncode == 0, out.stdout + out.stderr
    return out.stdout


def screen_shows(ring: str, endpoint: str, lines: list[str]) -> bool:
    return bool((from_terminal(tokenring_lcd(ring, endpoint, "--once")) == expected_screen(lines)).all())


def programs_by_node(ring: str, endpoint: str) -> dict[str, str | None]:
    """``tokenring status --json``: each node's running program (None: none runs)."""
    out = run_tokenring("status", "--ring", ring, "-e", endpoint, "--json", timeout=60)
    if out.returncode != 0:
        return {}
    return {node["name"]: node["program"] for node in json.loads(out.stdout)["nodes"]}


@pytest.mark.slow
@pytest.mark.timeout(400)  # its hang guards: three interpreters boot and load on a loaded machine
def test_up_no_start_waits_at_the_lcd_os_menu_until_start_robbi(procs, ring_name, endpoint, tmp_path):
    programs = tmp_path / "programs"
    programs.mkdir()
    for name, stamp in STAMPS.items():  # the programs, each with its own date
        shutil.copy(REPO / "modules" / f"{name}.py", programs / f"{name}.py")
        os.utime(programs / f"{name}.py", (stamp / 1000, stamp / 1000))
    output = tmp_path / "up.out"
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,map,lcd", "--no-world",
        "--programs", str(programs), "--no-start", "--duration", "300",
        stdout=output.open("w"),
    )  # fmt: skip

    def said() -> str:
        return output.read_text() if output.exists() else ""

    wait_until(lambda: "--no-start: the programs wait" in said(), 180, "the download to end")
    with tap(endpoint) as session:
        procs.watch(launcher_pids(session, ring_name))
        assert "changed: 3 of 3 program(s)" in said() and "started:" not in said(), said()

        # downloaded, not started: no program runs, the LCD shows its OS menu
        assert programs_by_node(ring_name, endpoint) == {"main": None, "map": None, "lcd": None}
        wait_until(lambda: screen_shows(ring_name, endpoint, OS_MENU), 60, "the OS V2.0 Main Menu")
        # ... and the web view's and Foxglove's /robot/lcd topic carries the OS menu's lines
        feed_lines = LcdSource(default_protocol()).poll(session, ring_name, 0)
        assert [m.data["lines"][:3] for m in feed_lines] == [OS_MENU], feed_lines

        # 2 Components: every node with its name, ID and program date
        tokenring_lcd(ring_name, endpoint, "--keys", "2")
        wait_until(
            lambda: screen_shows(ring_name, endpoint, COMPONENTS), 60, "the components with their dates"
        )
        tokenring_lcd(ring_name, endpoint, "--keys", "*")
        wait_until(lambda: screen_shows(ring_name, endpoint, OS_MENU), 60, "the OS menu again")
        assert programs_by_node(ring_name, endpoint) == {"main": None, "map": None, "lcd": None}

        # 1 Start Robbi, as up said to press it: every program starts, the lcd program's menu takes over
        hint = next(line for line in said().splitlines() if "1 (Start Robbi)" in line)
        command = shlex.split(hint.split("starts the programs: ", 1)[1])
        assert command[:2] == ["tokenring", "lcd"] and command[-2:] == ["--keys", "1"], hint
        pressed = subprocess.run([sys.executable, "-m", *command], capture_output=True, text=True, timeout=60)
        assert pressed.returncode == 0, pressed.stdout + pressed.stderr
        wait_until(
            lambda: (
                programs_by_node(ring_name, endpoint)
                == {"main": "Program", "map": "Program", "lcd": "Program"}
            ),
            60,
            "every program running",
        )
        wait_until(lambda: screen_shows(ring_name, endpoint, MAIN_MENU), 60, "the lcd program's Main Menu")
        resident = control(session, ring_name, 70, "resident")
        assert resident["error"] is None and resident["report"]["showing"] is False
    wait_until(lambda: "ARCNET_START_SYSTEM taken by [10, 60, 70]" in said(), 60, "the lcd node's log line")
    launcher.send_signal(signal.SIGTERM)
    assert launcher.wait(60) == 0


@pytest.mark.parametrize(
    ("options", "says"),
    [
        (["--no-download"], "there is no download (--no-download)"),
        (["--no-programs"], "there is no download (--no-programs)"),
        (["--nodes", "map,lcd"], "main, the PC link, is not among --nodes"),
        (["--explore", "2"], "--explore, --actions and --map-out need them running"),
    ],
)
def test_no_start_without_a_download_or_with_a_mission_is_one_clear_line(options, says):
    out = run_tokenring("up", "--no-start", *options, "--duration", "5", timeout=60)
    assert out.returncode == 2, out.stdout + out.stderr
    assert out.stdout == "" and len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert says in out.stderr and "Traceback" not in out.stderr, out.stderr
