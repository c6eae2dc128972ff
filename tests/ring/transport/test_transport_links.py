"""The token's hop on direct links (``tokenring node --link-listen/--link-connect``): real node
processes, clients of a router opened here, each linked to its successor in a second session.

The judge is the router: it subscribes every node's token key, so it sees exactly the frames
that went through it and none of those that went over a direct link.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from pathlib import Path

import pytest

from tests.support.ringutil import processes, stats, wait_until
from tokenring.transport.session import free_port
from tokenring.transport.zenoh_config import make_config, open_session

IDS = (10, 20, 30, 40)


@pytest.mark.slow
def test_the_hop_goes_direct_and_past_a_dead_successor_through_the_router(procs, ring_name, endpoint):
    ports: dict[int, int] = {}
    for node_id in IDS:
        ports[node_id] = free_port(avoid=ports.values())
    router = open_session(make_config(mode="router", listen=[endpoint]))
    through_router: list[str] = []
    lock = threading.Lock()

    def routed(sample) -> None:
        with lock:
            through_router.append(str(sample.key_expr))

    watcher = router.declare_subscriber(f"tokenring/{ring_name}/token/*", routed)
    try:
        nodes = {}
        for index, node_id in enumerate(IDS):
            successor = IDS[(index + 1) % len(IDS)]
            nodes[node_id] = procs.tokenring(
                *("node", "--id", str(node_id), "--ring", ring_name, "--bitrate", "max", "--no-store"),
                *("--mode", "client", "--connect", endpoint),
                *("--link-listen", f"tcp/127.0.0.1:{ports[node_id]}"),
                *("--link-connect", f"tcp/127.0.0.1:{ports[successor]}"),
            )

        def formed():
            found = stats(router, ring_name, 10)
            return found.get(10, {}).get("active") == list(IDS) and found[10]["stats"]["visits"] > 50

        wait_until(formed, 60.0, "a ring of four on direct links")
        with lock:
            through_router.clear()
        before = stats(router, ring_name, 10)[10]["stats"]["visits"]
        wait_until(
            lambda: stats(router, ring_name, 10)[10]["stats"]["visits"] > before + 200, 30.0, "200 rounds"
        )
        with lock:
            assert through_router == [], "with every node live, no frame should pass the router"

        nodes[20].send_signal(signal.SIGKILL)
        nodes[20].wait(30)

        def healed():
            found = stats(router, ring_name, 10)
            return found.get(10, {}).get("active") == [10, 30, 40] and found[10]["successor"] == 30

        wait_until(healed, 30.0, "node 10 passes to 30 past the killed 20")
        before = stats(router, ring_name, 10)[10]["stats"]["visits"]
        wait_until(
            lambda: stats(router, ring_name, 10)[10]["stats"]["visits"] > before + 50, 30.0, "circulating"
        )
        with lock:
            # 10 has no link to 30 (10 links to 20 and 40 links to 10): through the router
            assert f"tokenring/{ring_name}/token/30" in through_router
            assert f"tokenring/{ring_name}/token/10" not in through_router  # 40 -> 10 stays direct
        for node_id in (10, 30, 40):
            nodes[node_id].send_signal(signal.SIGTERM)
        for node_id in (10, 30, 40):
            assert nodes[node_id].wait(30) == 0
    finally:
        watcher.undeclare()
        router.close()


@pytest.mark.slow
def test_a_launched_ring_on_direct_links_circulates():
    from tokenring.perf.roundtrip import run_ring

    result = run_ring(6, 100, 20, router=True, links=True, timeout=120.0)
    assert len(result.rounds_s) == 100
    assert all(r > 0 for r in result.rounds_s)


def node_threads() -> dict[int, int]:
    """Threads of each node process this process started, by node ID (``/proc/PID/task``)."""
    found = {}
    for pid, (ppid, cmdline) in processes().items():
        command = cmdline.decode(errors="replace").split("\0")
        if ppid == os.getpid() and "--id" in command:
            with contextlib.suppress(OSError):  # (a process that ended meanwhile)
                found[int(command[command.index("--id") + 1])] = len(
                    list(Path(f"/proc/{pid}/task").iterdir())
                )
    return found


@pytest.mark.slow
def test_a_nodes_threads_do_not_grow_with_the_ring():
    # a node prepares a direct sender for each node that joins near it in the ring (in a small
    # ring, every other node); each sender's matching listener once had a Python thread of its
    # own: 30 threads per node at 12 nodes, and the first nodes of 255 held 268 (40 MB of RSS)
    from tokenring.perf.roundtrip import run_ring

    threads: dict[int, dict[int, int]] = {}
    for n in (4, 12):
        seen = threads[n] = {}
        run_ring(
            n,
            50,
            20,
            router=True,
            links=True,
            timeout=120.0,
            on_ready=lambda *_, s=seen: s.update(node_threads()),
        )
        assert len(seen) == n, seen
    assert max(threads[12].values()) <= max(threads[4].values()) + 2, threads


def test_links_are_refused_where_they_would_bypass_the_rings_rules(tmp_path):
    from tokenring.errors import UsageError
    from tokenring.host.launcher import Launcher

    for options in (
        {"links": True},
        {"links": True, "router": True, "zenoh_config": str(tmp_path / "z.json5")},
    ):
        with pytest.raises(UsageError):
            Launcher([], ring="t", listen=["tcp/127.0.0.1:1"], **options)


def test_the_launcher_links_each_node_to_its_successors_listener():
    from tokenring.host.launcher import Launcher, NodePlan

    launcher = Launcher(
        [NodePlan(i, f"node{i}", None) for i in (30, 10, 20)],
        ring="t",
        listen=["tcp/127.0.0.1:1"],
        router=True,
        links=True,
    )
    options = {i: launcher.link_options(i) for i in (10, 20, 30)}
    listens = {i: o[o.index("--link-listen") + 1] for i, o in options.items()}
    connects = {i: o[o.index("--link-connect") + 1] for i, o in options.items()}
    assert connects == {10: listens[20], 20: listens[30], 30: listens[10]}  # in ID order, round
    assert len(set(listens.values())) == 3
    assert launcher.link_options(20) == options[20]  # a respawned node listens where it did
