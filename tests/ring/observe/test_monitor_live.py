"""``tokenring monitor`` on a terminal: redrawn in place (no clear-screen flicker), in colour.

The monitor runs on a real pseudo-terminal against a real ring; the judge reads the bytes the
terminal got: ANSI SGR colour codes around an active fault and no clear-screen sequence.
"""

from __future__ import annotations

import io
import json
import os
import pty
import re
import select
import subprocess
import time

import pytest

from tests.support.processes import REPO, TOKENRING, run_tokenring
from tests.support.ringutil import tap, wait_ring
from tokenring.cli.commands.monitor import render_rich

CLEAR_SCREEN = "\x1b[2J"
ERASE_LINE = "\x1b[2K"
ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")
CURSOR_UP = re.compile(r"\x1b\[\d*A")
# an SGR sequence that turns on red (31) foreground, possibly with bold (1): "\x1b[1;31m", "\x1b[31m"
RED_THEN = r"\x1b\[(?:[0-9]+;)*31(?:;[0-9]+)*m[^\x1b]*"


def run_on_terminal(args: list[str], timeout: float = 90.0) -> tuple[int, str]:
    """Run a command with its stdout on a pseudo-terminal (80x24 is too narrow: 200x60)."""
    master, slave = pty.openpty()
    env = {k: v for k, v in os.environ.items() if k not in ("NO_COLOR", "COLUMNS", "LINES")}
    env.update(TERM="xterm-256color", COLUMNS="220", LINES="60", PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(
        args, stdout=slave, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, cwd=REPO, env=env
    )
    os.close(slave)
    chunks = []
    deadline = time.monotonic() + timeout
    try:
        while time.monotonic() < deadline:
            ready, _, _ = select.select([master], [], [], 0.5)
            if ready:
                try:
                    data = os.read(master, 65536)
                except OSError:  # the terminal closed: the process ended
                    break
                if not data:
                    break
                chunks.append(data)
            elif proc.poll() is not None:
                break
        code = proc.wait(timeout=max(1.0, deadline - time.monotonic()))
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
        os.close(master)
        if proc.stderr is not None:
            proc.stderr.close()
    return code, b"".join(chunks).decode("utf-8", "replace")


@pytest.fixture
def small_ring(procs, ring_name, endpoint):
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor,sonar", "--no-world",
        "--no-programs", "--duration", "120",
    )  # fmt: skip
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20, 30])
    yield ring_name, endpoint
    launcher.terminate()
    assert launcher.wait(30) == 0


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_a_terminal_gets_the_view_redrawn_in_place_with_the_fault_in_red(small_ring):
    ring, endpoint = small_ring
    fault = run_tokenring("fault", "motor", "delay", "1", "--ring", ring, "-e", endpoint, "--timeout", "5")
    assert fault.returncode == 0, fault.stderr
    common = ["--ring", ring, "-e", endpoint]
    code, screen = run_on_terminal([*TOKENRING, "monitor", "--count", "4", "--interval", "0.3", *common])
    assert code == 0, screen[-2000:]
    assert CLEAR_SCREEN not in screen  # the old view cleared the screen at every refresh: flicker
    # four refreshes (and the final one drawn again as the live view ends), each drawn over the
    # last (cursor up and erase line), not scrolled below it
    assert screen.count("tokenring monitor - ring") in (4, 5), screen[-2000:]
    assert len(CURSOR_UP.findall(screen)) >= 3 and ERASE_LINE in screen
    # motor's row ends with its active fault, in red
    assert re.search(RED_THEN + "delay", screen), screen[-3000:]
    assert "motor" in screen and "ring: main(10) -> motor(20) -> sonar(30) -> main(10)" in screen
    # --once on a terminal: one coloured snapshot, nothing to redraw
    code, once = run_on_terminal([*TOKENRING, "monitor", "--once", *common])
    assert code == 0 and once.count("tokenring monitor - ring") == 1
    assert re.search(RED_THEN + "delay", once) and not CURSOR_UP.search(once)
    # a pipe still gets plain text (what scripts and the older tests read)
    piped = run_tokenring("monitor", "--once", *common)
    assert piped.returncode == 0 and "\x1b[" not in piped.stdout and "delay" in piped.stdout

    # an excluded node's row is red: a real snapshot, one node marked excluded by another
    snaps = run_tokenring("monitor", "--json", "--count", "1", *common)
    snap = json.loads(snaps.stdout.splitlines()[0])
    snap["nodes"] = {int(k): v for k, v in snap["nodes"].items()}
    snap["faults"] = {int(k): v for k, v in snap["faults"].items()}
    snap["nodes"][10]["excluded"] = [30]
    events = [(time.time(), "FAULT START motor: delay"), (time.time(), "sonar (30) stopped answering")]
    from rich.console import Console

    out = io.StringIO()
    Console(file=out, force_terminal=True, color_system="standard", width=220).print(
        render_rich(ring, snap, events)
    )
    text = out.getvalue()
    assert re.search(RED_THEN + "excluded: 30", text)
    rows = {tuple(ANSI.sub("", line).split()[:2]): line for line in text.splitlines()}
    assert re.search(RED_THEN + "sonar", rows[("30", "sonar")]), repr(rows[("30", "sonar")])
    assert not re.search(RED_THEN + "main", rows[("10", "main")]), repr(rows[("10", "main")])
    assert re.search(RED_THEN + r" >> \S+  FAULT START motor: delay", text)
