"""The launcher's supervisor: children's exits wake it through pidfds, it does not poll them."""

from __future__ import annotations

import io
import sys
import time
from typing import ClassVar

from memring import wait_for

from tokenring.launcher import EXIT_CHECK_S, Launcher, NodePlan


class ShortLivedLauncher(Launcher):
    """Its "nodes" are tiny processes that exit after a given time: supervision is what is tested."""

    lifetimes: ClassVar[dict[int, float]] = {1: 0.3, 2: 60.0}

    def command_for(self, plan: NodePlan) -> list[str]:
        lifetime = self.lifetimes[plan.node_id]
        return [sys.executable, "-c", f"import time, sys; time.sleep({lifetime}); sys.exit(3)"]


def short_and_long(ring: str, endpoint: str, **options) -> ShortLivedLauncher:
    """A launcher of two children: "short" (id 1) exits with code 3 after 0.3 s, "long" lives on."""
    options.setdefault("output", io.StringIO())
    return ShortLivedLauncher(
        [NodePlan(1, "short", None), NodePlan(2, "long", None)], ring=ring, listen=[endpoint], **options
    )


def test_a_childs_exit_is_reported_at_once_without_polling_the_others(procs, ring_name, endpoint):
    output = io.StringIO()
    launcher = short_and_long(ring_name, endpoint, output=output)
    checks = 0
    check_children = launcher.check_children

    def counting_check() -> None:
        nonlocal checks
        checks += 1
        check_children()

    launcher.check_children = counting_check  # type: ignore[method-assign]
    launcher.start()
    try:
        procs.watch([c.process.pid for c in launcher.child_list()])
        short = launcher.children[1].process
        started = time.monotonic()
        wait_for(lambda: short.poll() is not None, 5.0, "the short-lived child to exit")
        exited = time.monotonic()
        wait_for(lambda: launcher.deaths, 2.0, "its death to be reported")
        assert time.monotonic() - exited < 0.2  # woken by its exit, not by a periodic check
        assert launcher.deaths == [("short", 1, 3)]
        time.sleep(1.0)
        # the old supervisor checked every child 20 times a second; now: the exit, and a
        # safety-net check every EXIT_CHECK_S
        assert checks <= 2 + (time.monotonic() - started) / EXIT_CHECK_S
    finally:
        launcher.stop()
    assert launcher.children[2].process.poll() is not None  # stop() ended the long-lived one
    assert "node short (id 1) exited with code 3" in output.getvalue()


def test_an_exit_is_reported_even_while_another_thread_polls_that_child(procs, ring_name, endpoint):
    # Popen.poll() answers None while another thread is inside poll() for the same child (a
    # status query, run()'s loop): the supervisor woken by the pidfd must still reap and report
    # it then, not at its next safety-net check a second later (this test's first version
    # polled beside the supervisor and failed that way once in a full suite run)
    from pathlib import Path

    launcher = short_and_long(ring_name, endpoint)
    launcher.start()
    try:
        procs.watch([c.process.pid for c in launcher.child_list()])
        short = launcher.children[1].process
        stat = Path(f"/proc/{short.pid}/stat")
        short._waitpid_lock.acquire()  # what another thread inside short.poll() holds
        try:
            wait_for(lambda: stat.read_text().rsplit(")", 1)[1].split()[0] == "Z", 5.0, "the child to exit")
            time.sleep(0.1)  # the supervisor has woken on the pidfd meanwhile
        finally:
            short._waitpid_lock.release()
        released = time.monotonic()
        wait_for(lambda: launcher.deaths, 2.0, "its death to be reported")
        assert time.monotonic() - released < 0.5  # not at the next check, EXIT_CHECK_S later
        assert launcher.deaths == [("short", 1, 3)]
    finally:
        launcher.stop()


def test_respawn_starts_a_dead_node_again_after_a_short_delay(procs, ring_name, endpoint):
    # systemd's RestartSec: the ring heals around the dead node first instead of sharing the
    # cores with a booting interpreter (crash recovery 21 ms with the delay, 27 ms without)
    from tokenring.launcher import RESPAWN_DELAY_S

    launcher = short_and_long(ring_name, endpoint, respawn=True)
    launcher.start()
    try:
        first = launcher.children[1]
        procs.watch([c.process.pid for c in launcher.child_list()])
        wait_for(lambda: first.process.poll() is not None, 5.0, "the short-lived child to exit")
        exited = time.monotonic()
        second = wait_for(lambda: launcher.children[1] is not first and launcher.children[1], 2.0, "respawn")
        procs.watch([second.process.pid])
        assert second.restarts == 1
        assert RESPAWN_DELAY_S - 0.01 <= second.started - exited < RESPAWN_DELAY_S + 0.3
    finally:
        launcher.stop()
