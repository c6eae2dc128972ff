"""Two rings, one name: a second ``up`` of a ring that runs on the same Zenoh network, or a node
under an ID that is live there, is refused in one line naming who holds it (issue 52), and the
ring that runs goes on: its eight nodes, one token.

One ring runs for the whole module (booting eight interpreters is the slow part); each test
tries one way in and then judges that ring again.
"""

from __future__ import annotations

import io
import os
import signal
import time
import uuid
from collections.abc import Iterator
from dataclasses import dataclass

import pytest
import zenoh

from tests.support.processes import Processes, run_tokenring
from tests.support.ringjudge import FrameTap, Header, one_token
from tests.support.ringutil import control, launcher_pids, stats, tap, wait_ring, wait_until
from tokenring.contract.protocol import default_protocol
from tokenring.errors import UsageError
from tokenring.host.launcher import Launcher, NodePlan
from tokenring.transport.session import free_port

IDS = sorted(n.id for n in default_protocol().default_nodes)
HEADER = Header.from_protocol()

pytestmark = pytest.mark.slow


@dataclass
class HeldRing:
    name: str
    endpoint: str
    launcher_pid: int
    node_pids: list[int]
    session: zenoh.Session
    frames: FrameTap

    @property
    def env(self) -> dict[str, str]:
        """A second launcher's environment: the same default endpoint, so its port is taken."""
        return dict(os.environ, TOKENRING_ENDPOINT=self.endpoint)

    def still_whole(self) -> None:
        """The ring runs on: the same launcher and node processes, and one token through all."""
        status = control(self.session, self.name, "launcher", "status")
        assert status["pid"] == self.launcher_pid
        assert sorted(n["pid"] for n in status["nodes"] if n["running"]) == sorted(self.node_pids)
        assert set(stats(self.session, self.name)) == set(IDS)
        last = []

        def one() -> bool:
            verdict = one_token(self.frames.snapshot(since=time.perf_counter() - 1.0), HEADER, IDS)
            last[:] = [verdict]
            return verdict.ok

        try:
            wait_until(one, 30, f"one token through {IDS}", interval=0.25)
        except AssertionError as exc:
            raise AssertionError(f"{exc}\n{last[0] if last else ''}") from None


@pytest.fixture(scope="module")
def held() -> Iterator[HeldRing]:
    processes = Processes()
    name = f"t{uuid.uuid4().hex[:10]}"
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    launcher = processes.tokenring(
        "up", "--ring", name, "--no-programs", "--no-world", env={"TOKENRING_ENDPOINT": endpoint}
    )
    session = tap(endpoint)
    try:
        wait_ring(session, name, IDS, timeout=120)
        pids = launcher_pids(session, name)
        processes.watch(pids)
        frames = FrameTap(session, name)
        yield HeldRing(name, endpoint, launcher.pid, pids, session, frames)
        frames.close()
    finally:
        session.close()
        launcher.send_signal(signal.SIGTERM)
        launcher.wait(30)
        leaked = processes.cleanup()
    assert launcher.returncode == 0, launcher.returncode
    assert not leaked, leaked


def refused(result, *parts: str) -> str:
    """The one line a refused command wrote: exit 2, no traceback, naming every part."""
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, (result.returncode, result.stdout, result.stderr)
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    for part in parts:
        assert part in lines[0], (part, lines[0])
    return lines[0]


def test_a_second_up_of_the_ring_on_its_taken_port_is_refused_naming_the_holder(held):
    # the documented path: the port is taken, so the second up joins that network ... where its
    # ring already runs
    result = run_tokenring("up", "--ring", held.name, "--no-programs", "--no-world", env=held.env)
    line = refused(result, f"ring {held.name!r} is in use", f"launcher pid {held.launcher_pid}", "host ")
    assert "live there" in line  # its IDs are the running ring's: all eight
    assert "is taken: joining that Zenoh network" in result.stdout
    assert "starting" not in result.stdout  # refused before any node started
    held.still_whole()


def test_a_second_launcher_of_the_ring_with_other_ids_is_refused_unless_it_joins_on_purpose(
    held, monkeypatch
):
    # a ring's name is not taken over with IDs it does not run either (in-process: the robot's
    # protocol has no ninth node for a second `up` to start)
    monkeypatch.setenv("TOKENRING_ENDPOINT", held.endpoint)
    output = io.StringIO()
    launcher = Launcher([NodePlan(90, "stranger")], ring=held.name, output=output)
    with pytest.raises(UsageError) as refusal:
        launcher.start()
    line = str(refusal.value)
    assert f"ring {held.name!r} is in use" in line and f"launcher pid {held.launcher_pid}" in line
    assert "--connect" in line and launcher.child_list() == [] and launcher.session is None
    held.still_whole()


def test_joining_a_ring_on_purpose_is_refused_the_ids_that_are_live_there(held):
    # --connect joins on purpose (one launcher per host): only its live IDs are refused
    result = run_tokenring(
        "up",
        "--ring",
        held.name,
        "--no-programs",
        "--no-world",
        "--connect",
        held.endpoint,
        "--nodes",
        "motor,sonar",
        env=held.env,
    )
    refused(result, f"ring {held.name!r} is in use", "node ID(s) 20, 30", f"launcher pid {held.launcher_pid}")
    held.still_whole()


def test_a_node_under_a_live_id_is_refused_naming_its_holder(held):
    motor = stats(held.session, held.name, 20)[20]
    result = run_tokenring(
        "node", "--id", "20", "--ring", held.name, "--connect", held.endpoint, "--no-store", env=held.env
    )
    refused(result, "node ID 20 is already live", f"ring {held.name!r}", f"pid {motor['pid']}")
    held.still_whole()
