"""The bare rings of direct successor links (``roundtrip_bare --mode chain`` and ``links``)
circulate and end, and a bare ring whose process fails ends the wait at once."""

import os
import subprocess
import sys

import pytest

from tests.support.ringutil import processes
from tokenring.perf.roundtrip import run_bare


def children_running(marker: bytes) -> list[int]:
    """PIDs of this process's children whose command line holds ``marker``."""
    me = os.getpid()
    return [pid for pid, (ppid, cmdline) in processes().items() if ppid == me and marker in cmdline]


@pytest.mark.slow
@pytest.mark.parametrize("router", [False, True], ids=["chain", "links"])
def test_a_chain_of_direct_links_passes_the_frame_round_and_every_process_ends(router):
    rounds = run_bare(8, 30, 5, timeout=60.0, chain=True, router=router)
    assert len(rounds) == 30
    assert all(r > 0 for r in rounds)
    assert children_running(b"tokenring.perf.bare_ring") == []


def test_a_process_of_a_bare_ring_that_fails_ends_the_wait_at_once():
    from tokenring.perf.roundtrip import _wait_first

    first = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    failing = subprocess.Popen([sys.executable, "-c", "import sys; sys.exit(3)"])
    waiting = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        assert _wait_first(first, [waiting, failing], timeout=60) == (2, 3)
        assert first.poll() is None  # it did not wait for process 0 to end
    finally:
        for proc in (first, failing, waiting):
            proc.kill()
            proc.wait()


def test_ports_drawn_for_a_255_process_chain_never_repeat():
    from tokenring.transport.session import free_port

    ports: list[int] = []
    for _ in range(255):
        ports.append(free_port(avoid=ports))
    assert len(set(ports)) == 255
