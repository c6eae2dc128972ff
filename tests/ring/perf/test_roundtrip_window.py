"""The rounds ``tokenring bench`` reports are the rounds it measured: what it does after the
window (reading every node's /proc, a caller's ``on_ready``) must not land in them."""

from __future__ import annotations

import os
import signal
import time

import pytest

from tests.support.ringutil import processes

STALL_S = 0.5  # under the second a frozen node sleeps through without asking to rejoin


def node_pids() -> list[int]:
    """The node processes this process started (their command lines name an ``--id``)."""
    return [
        pid
        for pid, (ppid, cmdline) in processes().items()
        if ppid == os.getpid() and b"--id" in cmdline.split(b"\0")
    ]


@pytest.mark.slow
def test_what_follows_the_window_is_not_in_its_rounds():
    from tokenring.perf.roundtrip import run_ring

    stalled: list[int] = []

    def stall_the_ring(_session, _ring) -> None:
        # an observer that holds every node still after the window, as reading 255 processes'
        # smaps_rollup did for a few rounds: those rounds came last in the list and set the p99
        pids = node_pids()
        for pid in pids:
            os.kill(pid, signal.SIGSTOP)
        time.sleep(STALL_S)
        for pid in pids:
            os.kill(pid, signal.SIGCONT)
        stalled.extend(pids)

    result = run_ring(3, 200, 20, timeout=120.0, on_ready=stall_the_ring)
    assert len(stalled) == 3, stalled
    assert len(result.rounds_s) == 200
    # a round that spanned the stall would be at least STALL_S long; a 3-node round is ~1 ms
    assert max(result.rounds_s) < STALL_S, sorted(result.rounds_s)[-3:]
