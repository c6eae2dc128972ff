"""``tokenring console`` in a real terminal (tmux) on a live ring: the seed's keys (table 8.2) move
the simulated robot, the panels follow, and ``x`` quits leaving the ring running.

The judge of the robot's motion is the world's ground truth (``world/truth`` on Zenoh, read here
by hand), never the console's own panels; the screen is read as text (``capture-pane``).
"""

from __future__ import annotations

import math
import os
import re
import shlex
import shutil
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.support.processes import REPO, TOKENRING, pid_alive, wait_gone
from tests.support.ringutil import launcher_pids, tap, wait_ring
from tests.support.worldtruth import OPEN_HALL, Truth, close


class Terminal:
    """One tmux server of the test's own (its socket named after the session: the user's tmux and
    its window sizes are never involved) running one command; keys in, screen text out."""

    def __init__(self, name: str, command: str, width: int = 200, height: int = 50) -> None:
        self.name = name
        self.tmux = ["tmux", "-L", name, "-f", "/dev/null"]
        subprocess.run(
            [*self.tmux, "new-session", "-d", "-s", name, "-x", str(width), "-y", str(height), command],
            check=True,
            cwd=REPO,
        )
        out = subprocess.run(
            [*self.tmux, "display-message", "-p", "-t", name, "#{pane_pid}"],
            capture_output=True,
            text=True,
            check=True,
        )
        self.shell_pid = int(out.stdout.strip())

    def keys(self, *keys: str) -> None:
        subprocess.run([*self.tmux, "send-keys", "-t", self.name, *keys], check=True)

    def screen(self) -> str:
        out = subprocess.run(
            [*self.tmux, "capture-pane", "-p", "-t", self.name], capture_output=True, text=True
        )
        return out.stdout

    def wait_for(self, pattern: str, timeout: float = 60.0, differs: tuple | None = None) -> re.Match[str]:
        """The screen's first match of ``pattern`` once there is one (whose groups are not
        ``differs``, if given)."""
        deadline = time.monotonic() + timeout
        while True:
            match = re.search(pattern, self.screen())
            if match and (differs is None or match.groups() != differs):
                return match
            if time.monotonic() > deadline:
                raise AssertionError(f"the screen never showed {pattern!r}:\n{self.screen()}")
            time.sleep(0.2)

    def close(self) -> None:
        subprocess.run([*self.tmux, "kill-server"], capture_output=True)


@pytest.fixture
def terminal_name(ring_name: str) -> Iterator[list[Terminal]]:
    if shutil.which("tmux") is None:
        pytest.fail("tmux is not installed (Debian package tmux): the console is tested in a real terminal")
    opened: list[Terminal] = []
    yield opened
    for term in opened:
        term.close()
        assert not wait_gone([term.shell_pid], 5.0), (
            f"the console's shell {term.shell_pid} outlived its terminal"
        )


@pytest.mark.slow
@pytest.mark.timeout(600)  # its hang guards: three interpreters boot and load, then five drives
def test_console_keys_drive_the_robot_and_x_leaves_the_ring_running(
    procs, ring_name, endpoint, tmp_path: Path, terminal_name: list[Terminal]
) -> None:
    room = tmp_path / "hall.yaml"
    room.write_text(OPEN_HALL)
    action = tmp_path / "leg.act"
    action.write_text("# bound to a\ns 300\n")
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor,sonar,copro",
        "--world", str(room), "--bitrate", "max", "--duration", "900",
    )  # fmt: skip
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20, 30, 50], timeout=180)
        procs.watch(launcher_pids(session, ring_name))
        truth = Truth(session, ring_name)
        exit_file = tmp_path / "console.exit"
        command = " ".join(
            shlex.quote(part)
            for part in [
                *TOKENRING,
                "console",
                "--ring",
                ring_name,
                "--connect",
                endpoint,
                "--action",
                str(action),
            ]
        )
        term = Terminal(f"con-{ring_name}", f"{command}; echo $? > {shlex.quote(str(exit_file))}")
        terminal_name.append(term)
        odometry = term.wait_for(r"odometry +steps (-?\d+) / (-?\d+)", timeout=120)
        start = truth.wait(lambda p: True, "reported a pose")

        term.keys("e")
        term.wait_for(r"motors on")
        term.keys("Up", "Up")
        moved = truth.wait(lambda p: p[0] > start[0] + 30, "drove forward on ↑")
        term.keys("Left")
        truth.wait(lambda p: p[2] > moved[2] + math.radians(3), "turned left on ←")
        term.wait_for(r"odometry +steps (-?\d+) / (-?\d+)", differs=odometry.groups())  # the panel follows

        term.keys("s")  # a square queued behind nothing: it starts, its legs wait in the queue
        term.wait_for(r"▶ s 1000")
        term.keys("Space")
        term.wait_for(r"stopped; the queue is cleared")
        term.wait_for(r"\(queue empty\)")
        stopped = truth.settled()
        assert truth.settled() == pytest.approx(stopped, abs=0.5), "the robot went on after space"

        term.keys("a")  # the action file: 300 mm straight on
        term.wait_for(r"queued .*leg\.act")
        truth.wait(lambda p: math.dist(p[:2], stopped[:2]) > 250, "drove the action file's leg")
        term.wait_for(r"navigator (IDLE|DONE)", timeout=120)
        leg_end = truth.settled()
        assert math.dist(leg_end[:2], stopped[:2]) == pytest.approx(300, abs=40)

        term.keys("d")
        term.wait_for(r"motors off")
        term.keys("Up")
        term.wait_for(r"refused, the motors are off")
        assert close(truth.settled(), leg_end), "the robot moved with its motors off"

        term.keys("z")
        term.wait_for(r"key z means nothing")

        console_pids = _children(term.shell_pid)
        term.keys("x")
        deadline = time.monotonic() + 30
        while not exit_file.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        assert exit_file.read_text().strip() == "0", term.screen()
        assert not wait_gone(console_pids, 10.0), "the console left processes behind"
        assert launcher.poll() is None and all(pid_alive(p) for p in launcher_pids(session, ring_name))
        wait_ring(session, ring_name, [10, 20, 30, 50], timeout=30)  # the ring goes on without it

        # a closed terminal (SIGHUP) ends a second console; the ring goes on, nothing is left
        second = Terminal(f"con2-{ring_name}", command)
        terminal_name.append(second)
        second.wait_for(r"odometry +steps", timeout=120)
        console_pids = [second.shell_pid, *_children(second.shell_pid)]  # tmux runs it as the pane's process
        second.close()
        assert not wait_gone([second.shell_pid, *console_pids], 10.0), "a closed terminal left the console"
        wait_ring(session, ring_name, [10, 20, 30, 50], timeout=30)

        # the seed's stdout interface, keys by name from a pipe: the messages (table B.5's lines,
        # those said before it started too) and what each key did
        plain = subprocess.run(
            [*TOKENRING, "console", "--ring", ring_name, "--connect", endpoint, "--ui", "stdout"],
            input="e\nspace\nx\n",
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert plain.returncode == 0, plain.stderr
        lines = plain.stdout.splitlines()
        said = [line for line in lines if line in ("motors on", "stopped; the queue is cleared", "quit")]
        assert said == ["motors on", "stopped; the queue is cleared", "quit"], plain.stdout
        assert any(re.fullmatch(r"I +\d+ localisation started: .*", line) for line in lines), plain.stdout
    launcher.terminate()
    assert launcher.wait(60) == 0


@pytest.mark.slow
@pytest.mark.timeout(400)  # its hang guards: three interpreters boot and load
def test_up_console_takes_the_terminal_and_x_stops_the_ring(
    ring_name, endpoint, tmp_path: Path, terminal_name: list[Terminal]
) -> None:
    room = tmp_path / "hall.yaml"
    room.write_text(OPEN_HALL)
    exit_file = tmp_path / "up.exit"
    up = [
        *TOKENRING, "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor,sonar",
        "--world", str(room), "--bitrate", "max", "--duration", "600", "--console",
    ]  # fmt: skip
    command = " ".join(shlex.quote(part) for part in up)
    term = Terminal(f"up-{ring_name}", f"{command}; echo $? > {shlex.quote(str(exit_file))}; sleep 60")
    terminal_name.append(term)
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20, 30], timeout=240)
        launchers = launcher_pids(session, ring_name)
        nodes = [p for p in _children(term.shell_pid) if p not in launchers]
    term.wait_for(r"odometry +steps", timeout=120)
    term.keys("e")
    term.wait_for(r"motors on")
    term.keys("x")
    deadline = time.monotonic() + 60
    while not exit_file.exists() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert exit_file.exists() and exit_file.read_text().strip() == "0", term.screen()
    assert re.search(r"the console ended \(exit code 0\): stopping the ring", term.screen())
    assert not wait_gone([*launchers, *nodes], 10.0), "x left processes of the ring running"


def _children(pid: int) -> list[int]:
    """Every descendant of ``pid`` (by /proc), for the check that quitting leaves none."""
    found: list[int] = []
    frontier = [pid]
    while frontier:
        parent = frontier.pop()
        for entry in os.listdir("/proc"):
            if not entry.isdigit():
                continue
            try:
                stat = Path(f"/proc/{entry}/stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == parent:
                found.append(int(entry))
                frontier.append(int(entry))
    return found
