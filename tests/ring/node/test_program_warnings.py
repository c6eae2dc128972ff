"""Programs that misbehave are named for what they are: a ``setup()`` that never returns shows as
SETTING_UP (``status``, ``load``'s scan) and is warned about in the launcher's output; a
``<node>.py`` that is a symbolic link loop is refused, not skipped; a programs folder with nothing
for the ring says so instead of "every program is up to date"."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import threading
from pathlib import Path

import pytest

from tests.support.processes import REPO, TOKENRING
from tests.support.refusal import refusal_line, run_refused
from tests.support.ringutil import launcher_pids, stats, tap, wait_ring, wait_until
from tokenring.errors import UsageError
from tokenring.host.loader import check_program_dir
from tokenring.node.program_host import SETUP_WARNING_S

SETUP_BLOCKS = """
from tokenring import UserProgram


class Program(UserProgram):
    module = "motor"

    def setup(self):
        self.stop_requested.wait()  # a setup that blocks: it returns only when the node stops it
"""


class Lines:
    """A process's output lines as they come (a reader thread), to wait for one."""

    def __init__(self, stream) -> None:
        self.lines: list[str] = []
        self._thread = threading.Thread(target=self._read, args=(stream,), daemon=True)
        self._thread.start()

    def _read(self, stream) -> None:
        for line in stream:
            self.lines.append(line.rstrip("\n"))

    def having(self, *needles: str) -> list[str]:
        return [line for line in self.lines if all(n in line for n in needles)]


def tool(ring: str, endpoint: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*TOKENRING, *args, "--ring", ring, "-e", endpoint], capture_output=True, text=True, timeout=120
    )


@pytest.mark.slow
@pytest.mark.timeout(400)  # its hang guards: two interpreters boot and load on a loaded machine
def test_a_setup_that_never_returns_an_empty_folder_and_a_link_loop_are_named(
    procs, ring_name, endpoint, tmp_path
):
    programs = tmp_path / "programs"
    programs.mkdir()
    shutil.copy(REPO / "modules" / "main.py", programs / "main.py")
    (programs / "motor.py").write_text(SETUP_BLOCKS)
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor", "--no-world",
        "--bitrate", "max", "--programs", str(programs), "--store", str(tmp_path / "store"),
    )  # fmt: skip
    output = Lines(launcher.stdout)
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20], timeout=120)
        procs.watch(launcher_pids(session, ring_name))
        wait_until(
            lambda: stats(session, ring_name, 20).get(20, {}).get("program_state") == "setting up",
            120,
            "motor's program to be started (and stuck in its setup)",
        )
    status = tool(ring_name, endpoint, "status")
    assert status.returncode == 0, status.stderr
    assert "Program (SETTING_UP" in next(line for line in status.stdout.splitlines() if "motor" in line)

    # after the bound the launcher's output says what it is, once, naming the node
    wait_until(lambda: output.having("motor", "setup() has not returned after"), 120, "the warning")
    assert f"{SETUP_WARNING_S:.0f} s" in output.having("setup() has not returned")[0]
    status = tool(ring_name, endpoint, "status")
    assert (
        status.returncode == 0 and "warning: motor (20): setup() of Program has not returned" in status.stderr
    )
    scan = tool(ring_name, endpoint, "load")
    assert scan.returncode == 0, scan.stderr
    assert "SETTING_UP" in next(line for line in scan.stdout.splitlines() if line.strip().startswith("motor"))

    # a folder with no programs, and one with programs for no node on the ring
    empty = tmp_path / "empty"
    empty.mkdir()
    result = tool(ring_name, endpoint, "load", "-i", "--programs", str(empty), "--no-progress")
    assert result.returncode == 0, result.stderr
    assert f"nothing to send: {empty} holds no programs" in result.stdout
    assert "up to date" not in result.stdout
    others = tmp_path / "others"
    others.mkdir()
    (others / "sonar.py").write_text("from tokenring import UserProgram\n\nclass P(UserProgram):\n    pass\n")
    result = tool(ring_name, endpoint, "load", "-i", "--programs", str(others), "--no-progress")
    assert result.returncode == 0, result.stderr
    assert (
        f"no program in {others} is for a node on the ring (sonar.py; the ring: main, motor)" in result.stdout
    )

    # main.py a symbolic link loop: refused in one line naming it, nothing sent
    looped = tmp_path / "looped"
    looped.mkdir()
    os.symlink("main.py", looped / "main.py")
    result = tool(ring_name, endpoint, "load", "-i", "--programs", str(looped), "--no-progress")
    assert result.returncode == 2 and "Traceback" not in result.stderr, result.stderr
    assert result.stderr.strip().splitlines() == [
        f"tokenring load: error: {looped / 'main.py'}: a symbolic link loop, not the program of node 'main'"
    ]
    launcher.terminate()
    launcher.wait(60)


def test_up_refuses_a_program_that_is_a_link_loop_or_leads_nowhere_before_anything_starts(tmp_path):
    programs = tmp_path / "programs"
    programs.mkdir()
    os.symlink("main.py", programs / "main.py")
    refusal_line(
        run_refused("up", "--programs", str(programs), "--no-world"), "main.py", "symbolic link loop"
    )
    (programs / "main.py").unlink()
    os.symlink(tmp_path / "gone.py", programs / "motor.py")
    refusal_line(
        run_refused("up", "--programs", str(programs), "--no-world"),
        "motor.py",
        f"a symbolic link to {tmp_path / 'gone.py'}, which does not exist",
    )


def test_check_program_dir_names_what_is_not_a_program(tmp_path: Path):
    (tmp_path / "main.py").write_text("")
    (tmp_path / "motor.py").mkdir()
    assert check_program_dir(tmp_path, ["main", "sonar"]) == {"main": tmp_path / "main.py"}
    with pytest.raises(UsageError, match=re.escape("motor.py: a directory, not the program of node 'motor'")):
        check_program_dir(tmp_path, ["main", "motor"])
