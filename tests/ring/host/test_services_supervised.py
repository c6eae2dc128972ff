"""Every service ``up`` starts is supervised like a node (issue 52): the world simulator and the
recorder killed mid-run are each named in one line, the ring goes on, and the run's exit code
is 1; with ``--respawn`` a service that keeps no state (the web view) is started again, one that
does (the world, a recording) is not, and says why.
"""

from __future__ import annotations

import os
import signal

import pytest

from tests.support.processes import pid_alive, wait_gone
from tests.support.ringutil import control, launcher_pids, tap, wait_ring, wait_until
from tokenring.transport.session import free_port

pytestmark = pytest.mark.slow


def launcher_status(session, ring_name: str) -> dict:
    try:
        return control(session, ring_name, "launcher", "status", timeout=1.0)
    except AssertionError:  # not answering yet
        return {}


def services(session, ring_name: str) -> dict[str, dict]:
    return {s["name"]: s for s in launcher_status(session, ring_name).get("services", [])}


def said(session, ring_name: str, text: str) -> list[str]:
    return [line for line in launcher_status(session, ring_name).get("failures", []) if text in line]


def test_the_world_and_the_recorder_killed_mid_run_are_named_and_counted(
    procs, ring_name, endpoint, tmp_path
):
    recording = tmp_path / "run.mcap"
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor", "--no-programs",
        "--record", str(recording),
    )  # fmt: skip
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20], timeout=120)
        nodes = launcher_pids(session, ring_name)
        procs.watch(nodes)
        running = services(session, ring_name)
        assert set(running) == {"world", "watch"} and all(s["running"] for s in running.values())
        procs.watch([s["pid"] for s in running.values()])
        for name in ("world", "watch"):
            pid = running[name]["pid"]
            os.kill(pid, signal.SIGKILL)
            line = wait_until(lambda n=name: said(session, ring_name, f"service {n} "), 60, f"{name}'s death")
            assert line == [f"service {name} (pid {pid}) killed by SIGKILL: the ring goes on without it"]
        assert wait_gone([s["pid"] for s in running.values()], 30) == []
        assert launcher.poll() is None and wait_ring(session, ring_name, [10, 20])  # the ring goes on
        assert launcher_pids(session, ring_name) == nodes
    launcher.send_signal(signal.SIGTERM)
    output, _ = launcher.communicate(timeout=60)
    assert launcher.returncode == 1, output[-3000:]
    assert output.count("killed by SIGKILL: the ring goes on without it") == 2, output[-3000:]
    assert "Traceback" not in output


def test_respawn_restarts_the_web_view_but_not_the_world(procs, ring_name, endpoint):
    port = free_port()
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor", "--no-programs",
        "--respawn", "--web", "--web-port", str(port),
    )  # fmt: skip
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20], timeout=120)
        procs.watch(launcher_pids(session, ring_name))
        first = services(session, ring_name)
        procs.watch([s["pid"] for s in first.values()])
        os.kill(first["watch"]["pid"], signal.SIGKILL)

        def restarted() -> dict | None:
            watch = services(session, ring_name).get("watch", {})
            return watch if watch.get("running") and watch.get("restarts") == 1 else None

        again = wait_until(restarted, 60, "the web view started again")
        procs.watch([again["pid"]])
        assert again["pid"] != first["watch"]["pid"]
        assert said(session, ring_name, "service watch ")[0].endswith("killed by SIGKILL; restarting it")
        os.kill(first["world"]["pid"], signal.SIGKILL)
        line = wait_until(lambda: said(session, ring_name, "service world "), 60, "the world's death")
        assert "--respawn does not restart it" in line[0]
        world = services(session, ring_name)["world"]
        assert not world["running"] and world["restarts"] == 0
    launcher.send_signal(signal.SIGTERM)
    output, _ = launcher.communicate(timeout=60)
    assert launcher.returncode == 1, output[-3000:]
    assert not pid_alive(again["pid"])  # the restarted one is stopped with the rest
