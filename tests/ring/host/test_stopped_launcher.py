"""A launcher stopped by SIGSTOP (or Ctrl-Z) while its nodes go on: ``status`` tells the truth
(it asks the nodes directly, or says the launcher is stopped and is their router), and the
regenerations a stopped router causes are counted as the network's, not as spurious — the
launcher, resumed, says how long it stood still and tells its nodes."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import threading
import time
from types import SimpleNamespace

import pytest

from tests.support.processes import TOKENRING
from tests.support.ringutil import launcher_pids, stats, tap, wait_ring, wait_until
from tokenring.host.regeneration import ring_rates
from tokenring.node.regeneration import RegenerationLedger
from tokenring.transport.reach import diagnose
from tokenring.transport.session import free_port

IDS = [10, 20, 30, 40]
NODES = "main,motor,sonar,compass"


class Lines:
    """A process's output lines as they come (a reader thread)."""

    def __init__(self, stream) -> None:
        self.lines: list[str] = []
        threading.Thread(
            target=lambda: self.lines.extend(line.rstrip() for line in stream), daemon=True
        ).start()

    def having(self, needle: str) -> list[str]:
        return [line for line in list(self.lines) if needle in line]


def status(ring: str, endpoint: str) -> tuple[int, dict, str]:
    out = subprocess.run(
        [*TOKENRING, "status", "--json", "--ring", ring, "-e", endpoint],
        capture_output=True,
        text=True,
        timeout=120,
    )
    return out.returncode, json.loads(out.stdout), out.stderr


def settled(session, ring: str) -> dict | None:
    """Every node's stats once each has run longer than its ledger's quiet time (the joins at
    boot no longer explain a regeneration)."""
    found = stats(session, ring)
    ledgers = [n.get("regenerations", {}) for n in found.values()]
    if set(found) == set(IDS) and all(g.get("uptime_s", 0) > g.get("quiet_s", 1e9) + 1 for g in ledgers):
        return found
    return None


@pytest.fixture
def stopped(procs):
    """SIGSTOP a process by PID for the test, SIGCONT it at the end whatever happens."""
    held: list[int] = []

    def stop(pid: int) -> None:
        os.kill(pid, signal.SIGSTOP)
        held.append(pid)

    yield stop
    for pid in held:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGCONT)


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_status_asks_the_nodes_directly_past_a_stopped_launcher(procs, ring_name, endpoint, stopped):
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", NODES, "--no-world", "--no-programs"
    )  # fmt: skip
    output = Lines(launcher.stdout)
    with tap(endpoint) as session:
        wait_ring(session, ring_name, IDS, timeout=120)
        procs.watch(launcher_pids(session, ring_name))
        wait_until(lambda: settled(session, ring_name), 120, "the ring past its boot")
    stopped(launcher.pid)
    code, result, stderr = status(ring_name, endpoint)
    assert code == 0, stderr
    assert [n["id"] for n in result["nodes"]] == IDS  # every node, alive, answered
    assert f"(pid {launcher.pid}) holds {endpoint} but is stopped" in result["note"]
    assert stderr.strip().splitlines() == [f"status: {result['note']}"]
    assert f"kill -CONT {launcher.pid}" in result["note"]
    os.kill(launcher.pid, signal.SIGCONT)
    wait_until(
        lambda: output.having("the launcher did not run for"), 60, "the launcher to say it stood still"
    )
    code, result, stderr = status(ring_name, endpoint)
    assert code == 0 and result["note"] is None and stderr == "", stderr
    # peers pass the token to each other directly: a stopped launcher costs them no token
    assert result["regenerations"]["spurious"] == 0
    launcher.terminate()
    launcher.wait(60)


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_a_stopped_router_costs_regenerations_counted_as_the_networks(procs, ring_name, endpoint, stopped):
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--router", "--listen", endpoint, "--nodes", NODES, "--no-world",
        "--no-programs",
    )  # fmt: skip
    output = Lines(launcher.stdout)
    with tap(endpoint) as session:
        wait_ring(session, ring_name, IDS, timeout=120)
        procs.watch(launcher_pids(session, ring_name))
        before = ring_rates(
            wait_until(lambda: settled(session, ring_name), 120, "the ring past its boot").values()
        )
    assert before["spurious"] == 0
    stopped(launcher.pid)
    code, result, stderr = status(ring_name, endpoint)  # the router is the only way to the nodes
    assert code == 1 and result["nodes"] == [], stderr
    assert "is stopped" in result["note"] and "their router" in result["note"]
    # the fault: the router stands still for longer than the ring's slowest regeneration slot
    # (0.84 s + 3 ranks x 0.21 s); during it nothing can be observed of the nodes
    time.sleep(4.0)
    os.kill(launcher.pid, signal.SIGCONT)
    wait_until(
        lambda: output.having("the launcher did not run for"), 60, "the launcher to say it stood still"
    )
    assert "its nodes' router" in output.having("the launcher did not run for")[0]
    with tap(endpoint) as session:
        after = wait_until(
            lambda: (lambda r: r if r["network"] > before["network"] else None)(
                ring_rates(stats(session, ring_name).values())
            ),
            60,
            "the nodes to count the stall's regenerations as the network's",
        )
    assert after["spurious"] == 0, after
    assert after["regenerated"] - before["regenerated"] == after["network"] - before["network"], after
    launcher.terminate()
    launcher.wait(60)


def test_a_stall_told_afterwards_recounts_the_spurious_regenerations_in_it():
    os_ = SimpleNamespace(
        node_id=20,
        stats=SimpleNamespace(tokens_regenerated=0),
        timing=SimpleNamespace(current=SimpleNamespace(recon=0.084)),
        membership=SimpleNamespace(live={10, 20}, rank=lambda: 0),
        _live_changed_at=0.0,
    )
    ledger = RegenerationLedger(os_)  # type: ignore[arg-type]
    assert ledger.record(False) == "spurious"
    entry = ledger.recent[-1]
    assert ledger.note({"id": 0, "stalled": [entry["t"] - 1.0, entry["t"] + 0.5]}) == {
        "ok": True,
        "recounted": 1,
    }
    report = ledger.report()
    assert (report["spurious"], report["network"]) == (0, 1) and report["recent"][-1]["cause"] == "network"
    assert ledger.record(False) == "network"  # right after the stall, still its doing
    ledger.stalls.clear()
    assert ledger.record(False) == "spurious"
    # a span long past recounts nothing
    assert ledger.note({"id": 0, "stalled": [0.0, 1.0]})["recounted"] == 0


def test_diagnose_names_who_holds_a_local_port_or_that_nobody_does():
    with socket.socket() as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(("127.0.0.1", 0))
        sock.listen()
        port = sock.getsockname()[1]
        silence = diagnose(f"tcp/127.0.0.1:{port}")
        assert silence is not None and silence.pid == os.getpid() and not silence.stopped
        assert "but no Zenoh session answered there" in silence.describe()
    nobody = free_port()
    assert diagnose(f"tcp/127.0.0.1:{nobody}").describe() == (  # type: ignore[union-attr]
        f"nothing answers at tcp/127.0.0.1:{nobody}: no process of this host listens there"
    )
    assert diagnose("tcp/10.1.2.3:7447") is None  # another host: nothing to look at
