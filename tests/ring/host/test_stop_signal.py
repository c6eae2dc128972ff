"""A SIGTERM that the kernel hands to another thread of a node (one of Zenoh's) stops it too.

A signal sent to a process may land on any of its threads; Python runs the handler only on the
main thread, and only once that thread wakes. A node asleep on an endless wait for its stop
never woke: the launcher killed it after 1.5 s (CI saw "did not stop in 1.5 s: killing lcd").
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
from pathlib import Path

import pytest

from tests.support.ringutil import control, tap, wait_ring, wait_until

LIBC = ctypes.CDLL(None, use_errno=True)


def tgkill(pid: int, tid: int, signum: int) -> None:
    """Send ``signum`` to one thread ``tid`` of process ``pid`` (glibc's tgkill)."""
    if LIBC.tgkill(pid, tid, signum) != 0:
        raise OSError(ctypes.get_errno(), f"tgkill {pid} {tid}")


def zenoh_threads(pid: int) -> list[int]:
    """The threads of ``pid`` that Zenoh's runtime started: named by it, not "python"."""
    tids = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        name = (task / "comm").read_text().strip()
        if int(task.name) != pid and not name.startswith("python"):
            tids.append(int(task.name))
    return sorted(tids)


def stop_through_a_zenoh_thread(process) -> str:
    """SIGTERM to one of ``process``'s Zenoh threads; what it printed once it has exited 0."""
    others = zenoh_threads(process.pid)
    assert others, os.listdir(f"/proc/{process.pid}/task")
    tgkill(process.pid, others[0], signal.SIGTERM)
    output, _ = process.communicate(timeout=60)  # a hang guard: the old ones slept here forever
    assert process.returncode == 0, output[-2000:]
    return output


def test_a_sigterm_taken_by_a_zenoh_thread_still_stops_the_node(procs, ring_name, endpoint):
    node = procs.tokenring(
        "node", "--id", "10", "--ring", ring_name, "--listen", endpoint, "--bitrate", "max", "--no-store"
    )
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10])
    assert "node main left the ring" in stop_through_a_zenoh_thread(node)


@pytest.mark.timeout(120)  # a hang guard on reading its banner
def test_a_sigterm_taken_by_a_zenoh_thread_still_stops_the_world(procs, ring_name, endpoint):
    world = procs.start([sys.executable, "-m", "modules.world", "--ring", ring_name, "-l", endpoint])
    banner = world.stdout.readline()
    assert banner.startswith("world "), banner
    stop_through_a_zenoh_thread(world)


def main_thread_switches(pid: int) -> int:
    """How often the process's main thread has gone to sleep and been woken (the kernel's count)."""
    for line in Path(f"/proc/{pid}/task/{pid}/status").read_text().splitlines():
        if line.startswith("voluntary_ctxt_switches:"):
            return int(line.split()[1])
    raise AssertionError(f"no voluntary_ctxt_switches for {pid}")


@pytest.mark.slow
def test_an_idle_node_s_main_thread_sleeps_until_a_signal(procs, ring_name, endpoint):
    """The main thread waits for a signal without polling: while the node passes the token to
    itself a thousand times, it never wakes (it woke five times a second before)."""
    node = procs.tokenring(
        "node", "--id", "10", "--ring", ring_name, "--listen", endpoint, "--bitrate", "max", "--no-store"
    )
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10])
        visits = control(session, ring_name, 10, "visits")
        before = main_thread_switches(node.pid)
        wait_until(lambda: control(session, ring_name, 10, "visits") >= visits + 1000, 60, "1000 more visits")
        after = main_thread_switches(node.pid)
    assert after == before, f"the main thread woke {after - before} times"
    node.send_signal(signal.SIGTERM)
    output, _ = node.communicate(timeout=60)
    assert node.returncode == 0 and "node main left the ring" in output
