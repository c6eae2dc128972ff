"""Shared fixtures: unique ring names and ports, and process tracking that fails leaky tests.

Every process a test starts goes through :class:`Processes`; at teardown anything still running
(or any child a launcher reported that is still alive) is killed by PID and the test fails —
the shape of python-can's conftest that fails tests leaking a bus.
"""

from __future__ import annotations

import os
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.support.processes import REPO, Processes
from tokenring.transport.session import free_port as _free_port
from tokenring.transport.zenoh_config import RUNTIME_CHOSEN


@pytest.fixture(autouse=True, scope="session")
def program_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Node processes keep downloaded programs in a per-run directory, not in ~/.local/state."""
    store = tmp_path_factory.mktemp("store")
    os.environ["TOKENRING_STORE"] = str(store)
    return store


@pytest.fixture(autouse=True)
def zenoh_runtime_unchanged() -> Iterator[None]:
    """A test that runs the CLI in pytest's process sets the runtime variables there; later tests'
    processes must not inherit them (a node started by hand once ran the router's runtime)."""
    keys = ("ZENOH_RUNTIME", RUNTIME_CHOSEN)
    before = {key: os.environ.get(key) for key in keys}
    yield
    for key, value in before.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> Iterator[None]:
    """Keep each phase's report on the item, so fixtures can tell whether the test failed."""
    outcome = yield
    report = outcome.get_result()
    setattr(item, f"report_{report.when}", report)


@pytest.fixture
def procs(request: pytest.FixtureRequest) -> Iterator[Processes]:
    tracker = Processes()
    yield tracker
    call = getattr(request.node, "report_call", None)
    failed = call is not None and call.failed
    if failed:
        # shown under "Captured stdout teardown": what the ring said while the test failed
        print(tracker.unread_output())
    leaked = tracker.cleanup()
    if leaked and not failed:  # a failed test's processes are killed, not reported twice
        pytest.fail("test left processes running: " + "; ".join(leaked))


@pytest.fixture
def ring_name() -> str:
    return f"t{uuid.uuid4().hex[:10]}"


@pytest.fixture
def port() -> int:
    return _free_port()


@pytest.fixture
def endpoint(port: int) -> str:
    return f"tcp/127.0.0.1:{port}"


#: threads of an in-process node (tokenring.node, tokenring.node.system.layer loggers): a test module that leaves
#: one running keeps a ring circulating in this process and slows every later test's timing
NODE_THREAD_PREFIXES = ("watchdog-", "system-", "program-")


@pytest.fixture(autouse=True, scope="module")
def no_leaked_nodes() -> Iterator[None]:
    """Fail the module that leaves in-process nodes running (as ``procs`` does for processes)."""
    import threading

    yield
    deadline = time.monotonic() + 2.0
    while True:
        leaked = sorted(t.name for t in threading.enumerate() if t.name.startswith(NODE_THREAD_PREFIXES))
        if not leaked or time.monotonic() > deadline:
            break
        time.sleep(0.05)
    assert not leaked, f"in-process nodes left running (close their NodeOS): {leaked}"


#: tests/<tier>/...: the marker every test below a tier's folder carries
TIERS = ("ring", "robot", "bench", "meta")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark each test with its tier, from the folder it lives in."""
    for item in items:
        tier = item.path.relative_to(REPO / "tests").parts[0]
        if tier in TIERS:
            item.add_marker(tier)
