"""A tool's endpoint that does not answer: what holds it, and a ring's nodes reached past a
stopped launcher.

The tools reach a ring through its launcher's endpoint (``tcp/127.0.0.1:7447``). A launcher
stopped by SIGSTOP (or Ctrl-Z) still holds the port — the kernel accepts the connection — but
answers nothing, while its nodes, linked to each other directly, go on. On this host the
launcher is found through ``/proc``, and its nodes by the ports they listen on."""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field

import zenoh

from tokenring._util import procfs

LOCAL_HOSTS = ("127.0.0.1", "localhost", "[::1]", "::1", "0.0.0.0")


def local_port(endpoint: str) -> int | None:
    """The port of a TCP endpoint on this host (``tcp/127.0.0.1:7447``), else None."""
    scheme, _, address = endpoint.partition("/")
    host, _, port = address.rpartition(":")
    if scheme != "tcp" or host not in LOCAL_HOSTS or not port.isdigit():
        return None
    return int(port)


def answered(session: zenoh.Session, wait: float = 1.0) -> bool:
    """Whether the session linked to anyone (a peer or a router) within ``wait`` seconds."""
    deadline = time.monotonic() + wait
    while True:
        if list(session.info.peers_zid()) or list(session.info.routers_zid()):
            return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.05)


@dataclass
class Silence:
    """What holds an endpoint that answered nothing."""

    endpoint: str
    pid: int | None = None
    state: str | None = None  # /proc's letter: T stopped
    command: list[str] = field(default_factory=list)
    #: the endpoints its node processes listen on (they can be asked directly)
    node_endpoints: list[str] = field(default_factory=list)
    nodes: int = 0  # its node processes

    @property
    def stopped(self) -> bool:
        return self.state in ("T", "t")

    @property
    def who(self) -> str:
        words = self.command
        start = _tokenring_word(words)
        name = "tokenring " + " ".join(_verb(words[start + 1 :])) if start is not None else "a process"
        return f"{name.strip()} (pid {self.pid})"

    def describe(self) -> str:
        """One line: who holds the endpoint and why nothing answered."""
        if self.pid is None:
            return f"nothing answers at {self.endpoint}: no process of this host listens there"
        if self.stopped:
            line = f"{self.who} holds {self.endpoint} but is stopped (SIGSTOP or Ctrl-Z): it answers nothing"
            if self.nodes and not self.node_endpoints:
                line += f"; its {self.nodes} node(s) reach each other only through it (it is their router)"
            return line + f"; resume it with: kill -CONT {self.pid}"
        state = procfs.STATES.get(self.state or "", self.state or "gone")
        return f"{self.who} holds {self.endpoint} ({state}) but no Zenoh session answered there"


def _tokenring_word(words: list[str]) -> int | None:
    """Where ``tokenring`` (``-m tokenring``, or the console script's path) is in a command line."""
    for i, word in enumerate(words):
        if os.path.basename(word) == "tokenring":
            return i
    return None


def _verb(words: list[str]) -> list[str]:
    """The verb of ``tokenring``'s arguments (past ``--log-level LEVEL``), as a list of one or none."""
    rest = iter(words)
    for word in rest:
        if word == "--log-level":
            next(rest, None)
        elif not word.startswith("-"):
            return [word]
    return []


def diagnose(endpoint: str) -> Silence | None:
    """What holds ``endpoint`` on this host; None for an endpoint elsewhere (nothing to look at)."""
    port = local_port(endpoint)
    if port is None:
        return None
    pid = procfs.listener_pid(port)
    silence = Silence(endpoint, pid)
    if pid is None:
        return silence
    silence.state = procfs.process_state(pid)
    silence.command = procfs.command_line(pid)
    for child in procfs.child_pids(pid):
        words = procfs.command_line(child)
        start = _tokenring_word(words)
        if start is None or _verb(words[start + 1 :]) != ["node"]:
            continue  # a service (the world simulator, the watcher), not a node
        silence.nodes += 1
        silence.node_endpoints += [f"tcp/127.0.0.1:{p}" for p in procfs.listening_ports(child)]
    return silence
