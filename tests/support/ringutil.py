"""Helpers for tests that run real node processes over Zenoh on loopback."""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import zenoh

from tokenring.contract import keys
from tokenring.contract.protocol import default_protocol
from tokenring.transport.session import query
from tokenring.transport.zenoh_config import make_config, open_session


def tap(endpoint: str) -> zenoh.Session:
    """A peer session joined to the ring's tap endpoint (a tool's view of the ring)."""
    return open_session(make_config(connect=[endpoint]))


def stats(session: zenoh.Session, ring: str, node: int | str = "*", timeout: float = 1.0) -> dict[int, dict]:
    """Each answering node's ``stats`` by ID."""
    out = {}
    for _, reply in query(session, keys.control(ring, node, "stats"), timeout=timeout):
        if reply.get("ok"):
            out[reply["result"]["id"]] = reply["result"]
    return out


def control(session: zenoh.Session, ring: str, node: int | str, verb: str, timeout: float = 2.0) -> Any:
    replies = query(session, keys.control(ring, node, verb), timeout=timeout)
    assert replies, f"node {node} did not answer {verb}"
    reply = replies[0][1]
    assert reply.get("ok"), reply
    return reply["result"]


def wait_until(condition: Callable[[], Any], timeout: float, what: str, interval: float = 0.1) -> Any:
    deadline = time.monotonic() + timeout
    last = None
    while time.monotonic() < deadline:
        last = condition()
        if last:
            return last
        time.sleep(interval)
    raise AssertionError(f"timed out after {timeout} s waiting for {what} (last: {last!r})")


def wait_main_answers(link: Any, timeout: float = 120.0) -> None:
    """Wait until main's program answers its PC link (a ``state`` request)."""
    from tokenring.errors import UsageError

    def answers() -> bool:
        try:
            link.request("state")
            return True
        except UsageError:
            return False

    wait_until(answers, timeout, "main's program")


def wait_ring(
    session: zenoh.Session, ring: str, ids: list[int], timeout: float = 60.0, visits: int = 5
) -> dict:
    """Wait until every node in ``ids`` answers, sees all of them active and has the token.

    ``timeout`` is a hang guard, not a speed limit: eight interpreters booting on two loaded
    cores (the full suite beside other work) took over 20 s."""

    def formed() -> dict | None:
        found = stats(session, ring)
        if set(found) >= set(ids) and all(
            set(ids) <= set(found[i]["active"]) and found[i]["stats"]["visits"] >= visits for i in ids
        ):
            # under `tokenring up` the programs arrive over the ring first
            launcher = query(session, keys.control(ring, "launcher", "status"), timeout=0.5)
            if launcher and launcher[0][1].get("ok") and launcher[0][1]["result"].get("booting"):
                return None
            return found
        return None

    return wait_until(formed, timeout, f"ring {ring} with nodes {ids}")


def launcher_pids(session: zenoh.Session, ring: str) -> list[int]:
    status = control(session, ring, "launcher", "status")
    return [n["pid"] for n in status["nodes"]]


def answering_launcher_pids(session: zenoh.Session, ring: str) -> list[int]:
    """:func:`launcher_pids`, or none while the launcher does not answer yet (for wait_until)."""
    try:
        return launcher_pids(session, ring)
    except AssertionError:
        return []


def thread_names(pid: int) -> set[str]:
    """The names of a process's threads (``/proc/PID/task/*/comm``)."""
    names = set()
    for tid in os.listdir(f"/proc/{pid}/task"):
        with contextlib.suppress(OSError):
            names.add(Path(f"/proc/{pid}/task/{tid}/comm").read_text().strip())
    return names


PROBE_PROGRAM = '''
"""Test probe: writes its node ID into its data channel's first field, reads every other data
channel (lcd leaves sonar's locked), main sends commands to motor and sonar (whose inbox stays
locked), motor counts what it receives."""
import threading
import time

import numpy as np

from tokenring import UserProgram


class Program(UserProgram):
    def setup(self):
        os = self.os
        self.me = os.name
        self.out = os.publish()
        first = self.out.channel.fields[0]
        value = os.node_id
        self.out.write(**{first.name: [value] * first.dtype.shape[0] if first.dtype.shape else value})
        self.readers = {}
        for node in os.protocol.nodes.values():
            if node.name == self.me:
                continue
            if self.me == "lcd" and node.name == "sonar":
                self.readers[node.data.name] = os.get_data(node.data.name)  # stays locked
            else:
                self.readers[node.data.name] = os.subscribe(node.data.name)
        self.received = []
        self.results = {}
        if self.me == "sonar":
            os.set_own_input_id()  # registered, never unlocked
        elif self.me != "main":
            os.set_own_input_id()

    def run(self):
        os = self.os
        if self.me == "main":
            time.sleep(1.0)
            acked = sum(os.deliver("motor", "MOVE_FORWARD", distance_mm=d, speed_pct=10, timeout=5) for d in (1, 2, 3, 4, 5))
            self.results["motor_acked"] = acked
            box = os.send_command("sonar", "SET_METHOD", tangent=1, seed_classifier=1)
            box.done.wait(5)
            self.results["sonar_transmitted"] = os.command_transmitted("sonar")
            self.results["sonar_acknowledged"] = os.command_acknowledged("sonar")
        while self.running:
            if self.me == "sonar":
                self.sleep(0.1)
                continue
            cmd = os.receive_command(timeout=0.1)
            if cmd is not None:
                self.received.append([cmd.name, cmd.sender, cmd.args])

    def report(self):
        seen = {}
        for name, buffer in self.readers.items():
            first = buffer.channel.fields[0].name
            value = buffer[first]
            seen[name] = value[0] if isinstance(value, list) else value
        return {"seen": seen, "received": self.received, "results": self.results}
'''


def write_probe_programs(directory: Path) -> Path:
    """One probe program file per node of protocol.yaml, as ``tokenring up --programs`` wants."""
    directory.mkdir(parents=True, exist_ok=True)
    for node in default_protocol().nodes.values():
        (directory / f"{node.name}.py").write_text(PROBE_PROGRAM)
    return directory


def processes() -> dict[int, tuple[int, bytes]]:
    """Every process's parent PID and command line (read only)."""
    found = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
                cmdline = (entry / "cmdline").read_bytes()
            except (OSError, IndexError, ValueError):
                continue
            found[int(entry.name)] = (ppid, cmdline)
    return found
