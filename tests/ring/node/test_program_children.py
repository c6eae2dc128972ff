"""What a node's program starts ends with the node (issue 52): a child it forks, a grandchild
that outlived its own parent, one that ignores SIGTERM — none survives the node, whether the ring
stops, the node is killed (``kill -9``) while the ring runs, or the launcher itself is killed.

motor's program starts them in ``setup()`` and writes their PIDs to a file; the test judges
those PIDs. Each node leads a process group of its own for that, so the launcher forwards a
Ctrl-Z (SIGTSTP) and its continue to them itself.
"""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from tests.support.processes import pid_alive, wait_gone
from tests.support.ringutil import control, launcher_pids, tap, wait_ring, wait_until

pytestmark = pytest.mark.slow

#: motor's program: a child, an orphaned grandchild and a child deaf to SIGTERM, PIDs to PIDS
PROGRAM = """
import subprocess
from pathlib import Path

from tokenring import UserProgram

PIDS = Path({pids!r})


class Program(UserProgram):
    module = "motor"

    def setup(self):
        child = subprocess.Popen(["sleep", "600"])
        deaf = subprocess.Popen(["sh", "-c", "trap '' TERM; exec sleep 600"])
        starter = subprocess.run(
            ["sh", "-c", "sleep 600 >/dev/null 2>&1 & echo $!"], capture_output=True, text=True, check=True
        )
        orphan = int(starter.stdout)  # its parent, the shell, has exited
        PIDS.write_text(f"{{child.pid}} {{deaf.pid}} {{orphan}}")
"""


def start_ring(procs, ring_name: str, endpoint: str, tmp_path: Path):
    """`up` with motor running PROGRAM; (launcher, session, the PIDs its program started)."""
    programs = tmp_path / "programs"
    programs.mkdir()
    pids_file = tmp_path / "pids"
    (programs / "motor.py").write_text(PROGRAM.format(pids=str(pids_file)))
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor", "--no-world",
        "--no-download", "--programs", str(programs),
    )  # fmt: skip
    session = tap(endpoint)
    wait_ring(session, ring_name, [10, 20], timeout=120)
    procs.watch(launcher_pids(session, ring_name))
    text = wait_until(lambda: pids_file.exists() and pids_file.read_text(), 60, "the program's children")
    started = [int(pid) for pid in text.split()]
    procs.watch(started)  # killed by the fixture, and the test failed, if they outlive it
    assert all(pid_alive(pid) for pid in started)
    return launcher, session, started


def test_what_a_program_started_ends_when_the_ring_stops(procs, ring_name, endpoint, tmp_path):
    launcher, session, started = start_ring(procs, ring_name, endpoint, tmp_path)
    session.close()
    launcher.send_signal(signal.SIGTERM)
    output, _ = launcher.communicate(timeout=60)
    assert launcher.returncode == 0, output[-3000:]
    # nothing else would end them (sleep 600): the launcher did, the deaf one by SIGKILL
    assert wait_gone(started, 30) == [], output[-3000:]


def test_what_a_program_started_ends_when_its_node_is_killed(procs, ring_name, endpoint, tmp_path):
    launcher, session, started = start_ring(procs, ring_name, endpoint, tmp_path)
    with session:
        motor = control(session, ring_name, 20, "stats")["pid"]
        os.kill(motor, signal.SIGKILL)  # no clean leave: the node cannot end them itself
        assert wait_gone(started, 60) == [], "the program's children outlived their node"
        assert launcher.poll() is None  # the ring goes on without motor
        wait_ring(session, ring_name, [10], timeout=60)
    launcher.send_signal(signal.SIGTERM)
    output, _ = launcher.communicate(timeout=60)
    assert "node motor (id 20) killed by SIGKILL" in output, output[-3000:]
    assert launcher.returncode == 1  # a node died


def test_what_a_program_started_ends_when_the_launcher_is_killed(procs, ring_name, endpoint, tmp_path):
    # kill -9 of `up`: the nodes die of their parent-death signal, which cannot reach what their
    # programs started; the launcher's group keeper ends those
    launcher, session, started = start_ring(procs, ring_name, endpoint, tmp_path)
    nodes = launcher_pids(session, ring_name)
    session.close()
    launcher.kill()
    launcher.communicate(timeout=60)
    assert wait_gone([*nodes, *started], 60) == [], "processes outlived their killed launcher"


def state(pid: int) -> str:
    return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]


def test_ctrl_z_suspends_the_whole_ring_and_its_continue_resumes_it(procs, ring_name, endpoint):
    # the nodes lead their own process groups, out of the terminal's reach: the launcher
    # forwards the suspension, as the terminal did when they shared its group
    launcher = procs.tokenring(
        "up",
        "--ring",
        ring_name,
        "--listen",
        endpoint,
        "--nodes",
        "main,motor",
        "--no-world",
        "--no-programs",
    )
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20], timeout=120)
        nodes = launcher_pids(session, ring_name)
        procs.watch(nodes)
        launcher.send_signal(signal.SIGTSTP)
        wait_until(lambda: {state(p) for p in [launcher.pid, *nodes]} == {"T"}, 60, "the ring suspended")
        launcher.send_signal(signal.SIGCONT)
        wait_until(lambda: "T" not in {state(p) for p in [launcher.pid, *nodes]}, 60, "the ring continued")
        wait_ring(session, ring_name, [10, 20], timeout=60)
    launcher.send_signal(signal.SIGTERM)
    output, _ = launcher.communicate(timeout=60)
    assert launcher.returncode == 0, output[-3000:]
