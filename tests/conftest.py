"""Shared fixtures: unique ring names and ports, and process tracking that fails leaky tests.

Every process a test starts goes through :class:`Processes`; at teardown anything still running
(or any child a launcher reported that is still alive) is killed by PID and the test fails —
the shape of python-can's conftest that fails tests leaking a bus.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from tokenring.transport.session import free_port as _free_port
from tokenring.transport.zenoh_config import RUNTIME_CHOSEN

REPO = Path(__file__).resolve().parent.parent
TOKENRING = [sys.executable, "-m", "tokenring"]


def run_tokenring(*args: str, timeout: float = 60.0, **kwargs) -> subprocess.CompletedProcess:
    """Run one ``tokenring`` command to completion (text output captured), as a user would."""
    return subprocess.run([*TOKENRING, *args], capture_output=True, text=True, timeout=timeout, **kwargs)


def pid_alive(pid: int) -> bool:
    """True if ``pid`` exists and is not a zombie."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != "Z"


def wait_gone(pids: list[int], timeout: float) -> list[int]:
    deadline = time.monotonic() + timeout
    alive = [p for p in pids if pid_alive(p)]
    while alive and time.monotonic() < deadline:
        time.sleep(0.05)
        alive = [p for p in alive if pid_alive(p)]
    return alive


class Processes:
    """Starts processes for a test and guarantees they are gone afterwards."""

    def __init__(self) -> None:
        self.started: list[subprocess.Popen] = []
        self.extra_pids: set[int] = set()

    def start(self, args: list[str], **kwargs) -> subprocess.Popen:
        kwargs.setdefault("stdout", subprocess.PIPE)
        kwargs.setdefault("stderr", subprocess.STDOUT)
        kwargs.setdefault("text", True)
        kwargs.setdefault("cwd", REPO)
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        env.update(kwargs.pop("env", {}) or {})
        proc = subprocess.Popen(args, env=env, **kwargs)
        self.started.append(proc)
        return proc

    def tokenring(self, *args: str, **kwargs) -> subprocess.Popen:
        return self.start([*TOKENRING, *args], **kwargs)

    def watch(self, pids: list[int]) -> None:
        """Also make sure these PIDs (e.g. a launcher's children) are gone at teardown."""
        self.extra_pids.update(pids)

    def unread_output(self, limit: int = 16384) -> str:
        """What the still-open pipes hold (without blocking): the story of a failed test."""
        parts = []
        for proc in self.started:
            stream = proc.stdout
            if stream is None or stream.closed:
                continue
            try:
                os.set_blocking(stream.fileno(), False)
                text = stream.read() or ""
            except (OSError, ValueError, TypeError):
                continue
            if text:
                parts.append(f"--- pid {proc.pid}: {' '.join(map(str, proc.args))[:100]}\n{text[-limit:]}")
        return "\n".join(parts)

    def cleanup(self) -> list[str]:
        leaked: list[str] = []
        for proc in self.started:
            if proc.poll() is None:
                leaked.append(f"pid {proc.pid}: {' '.join(map(str, proc.args))[:120]}")
                with contextlib.suppress(ProcessLookupError):
                    proc.send_signal(signal.SIGTERM)
        for proc in self.started:
            try:
                proc.wait(3)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(3)
            for stream in (proc.stdout, proc.stderr):
                if stream is not None:
                    stream.close()
        for pid in wait_gone(sorted(self.extra_pids), 2.0):
            leaked.append(f"child pid {pid}")
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        return leaked


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
