"""The launcher's router keeps routing through a burst of messages that must not be dropped.

Zenoh blocks a sender of a message with blocking congestion control (a query, a declaration, a
reliable put) until the face it goes to has a free batch. On one worker thread that also sends
(tokenring's node runtime), the task that would free a batch needs that same worker, so a router
on it stalls for Zenoh's 5 s and then closes the face, losing what it had queued: the launcher's
answer to SIGCONT in the recovery benchmark never came. The launcher's process runs its own
runtime (tokenring.transport.zenoh_config.HOST_RUNTIME); this checks from outside, with plain Zenoh clients,
that every message of a burst arrives and the launcher still answers.
"""

from __future__ import annotations

import signal
import threading

import pytest
import zenoh

from tests.support.ringutil import answering_launcher_pids, launcher_pids, stats, thread_names, wait_until
from tokenring.transport.zenoh_config import HOST_RUNTIME, NODE_RUNTIME, RUNTIME_CHOSEN, node_environment

#: 20 MB in 1 KB messages: the burst that stalled a one-worker router in 1 of 1 runs here
#: (456 of 20 000 delivered, then the subscriber's face closed)
BURST = 20_000
SIZE = 1_000


def client(endpoint: str) -> zenoh.Session:
    """A plain Zenoh client of the router at ``endpoint``: no tokenring code between."""
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", f'["{endpoint}"]')
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("connect/timeout_ms", "60000")  # the launcher may not listen yet
    return zenoh.open(config)


def test_a_burst_of_reliable_puts_through_the_launchers_router_all_arrive(procs, ring_name, endpoint):
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--router", "--listen", endpoint,
        "--nodes", "main", "--no-world", "--no-programs",
    )  # fmt: skip
    key = f"{ring_name}/burst"
    received = 0
    all_in = threading.Event()

    def count(_sample: zenoh.Sample) -> None:
        nonlocal received
        received += 1
        if received == BURST:
            all_in.set()

    with client(endpoint) as listener, client(endpoint) as sender:
        procs.watch(
            wait_until(lambda: answering_launcher_pids(listener, ring_name), 60, "the launcher to answer")
        )
        subscriber = listener.declare_subscriber(key, count)
        publisher = sender.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
        wait_until(lambda: publisher.matching_status.matching, 30, "the publisher to see the subscriber")
        payload = b"x" * SIZE
        for _ in range(BURST):
            publisher.put(payload)
        arrived = all_in.wait(60)
        assert arrived, f"{received} of {BURST} reliable puts arrived through the launcher's router"
        assert launcher_pids(sender, ring_name), "the launcher stopped answering after the burst"
        subscriber.undeclare()
    assert launcher.poll() is None, "the launcher died"
    launcher.send_signal(signal.SIGTERM)
    assert launcher.wait(30) == 0


def test_a_node_gets_the_node_runtime_unless_a_runtime_was_set_after_tokenring_chose_one():
    chose = {"ZENOH_RUNTIME": HOST_RUNTIME, RUNTIME_CHOSEN: HOST_RUNTIME}
    assert node_environment({})["ZENOH_RUNTIME"] == NODE_RUNTIME
    assert node_environment(chose)["ZENOH_RUNTIME"] == NODE_RUNTIME
    assert RUNTIME_CHOSEN not in node_environment(chose)
    # a runtime set since (a user's, a test's) wins, even where a marker was inherited
    assert node_environment({**chose, "ZENOH_RUNTIME": "()"})["ZENOH_RUNTIME"] == "()"
    assert node_environment({"ZENOH_RUNTIME": "()"})["ZENOH_RUNTIME"] == "()"


@pytest.mark.parametrize(
    "inherited",
    [{}, {"ZENOH_RUNTIME": HOST_RUNTIME, RUNTIME_CHOSEN: HOST_RUNTIME}],
    ids=["own-shell", "shell-of-a-tokenring-process"],
)
def test_a_node_started_by_hand_sends_on_its_receiving_thread(procs, ring_name, endpoint, inherited):
    node = procs.tokenring(
        "--log-level", "warning", "node", "--id", "37", "--ring", ring_name, "--no-store", "--listen", endpoint,
        env=inherited,
    )  # fmt: skip
    with client(endpoint) as session:
        wait_until(lambda: stats(session, ring_name, 37), 60, "node 37 to answer")
        names = thread_names(node.pid)
    node.send_signal(signal.SIGTERM)
    assert node.wait(30) == 0
    assert "rx-0" in names and not any(n.startswith("tx-") for n in names), names
