"""Who holds a local TCP port, and in what state, from ``/proc`` (Linux): how a tool tells a
ring whose launcher is stopped (SIGSTOP, Ctrl-Z) from one that is not there, and finds the
launcher's nodes to ask them directly. Elsewhere every answer is "unknown" (None, empty)."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

PROC = Path("/proc")
LISTEN = "0A"  # the state column of /proc/net/tcp for a listening socket

#: /proc/PID/stat's state letters, as a person reads them
STATES = {
    "R": "running",
    "S": "sleeping",
    "D": "waiting on I/O",
    "T": "stopped",
    "t": "stopped by a debugger",
    "Z": "a zombie",
    "X": "dead",
    "I": "idle",
}


def _listeners() -> dict[int, list[int]]:
    """Socket inode -> the ports it listens on (IPv4 and IPv6)."""
    found: dict[int, list[int]] = {}
    for table in ("tcp", "tcp6"):
        try:
            lines = (PROC / "net" / table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            if len(fields) < 10 or fields[3] != LISTEN:
                continue
            with contextlib.suppress(ValueError):
                found.setdefault(int(fields[9]), []).append(int(fields[1].rsplit(":", 1)[1], 16))
    return found


def _socket_inodes(pid: int) -> set[int]:
    inodes: set[int] = set()
    try:
        entries = os.listdir(PROC / str(pid) / "fd")
    except OSError:
        return inodes
    for entry in entries:
        with contextlib.suppress(OSError, ValueError):
            target = os.readlink(PROC / str(pid) / "fd" / entry)
            if target.startswith("socket:["):
                inodes.add(int(target[8:-1]))
    return inodes


def listener_pid(port: int) -> int | None:
    """The process listening on TCP ``port`` (one of this user's, or any as root); None if none
    is, or it cannot be seen."""
    inodes = {inode for inode, ports in _listeners().items() if port in ports}
    if not inodes:
        return None
    for entry in PROC.iterdir():
        if entry.name.isdigit() and _socket_inodes(int(entry.name)) & inodes:
            return int(entry.name)
    return None


def listening_ports(pid: int) -> list[int]:
    """The TCP ports process ``pid`` listens on."""
    mine = _socket_inodes(pid)
    return sorted({port for inode, ports in _listeners().items() if inode in mine for port in ports})


def process_state(pid: int) -> str | None:
    """``pid``'s state letter (``T``: stopped), None if it is gone."""
    try:
        return (PROC / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return None


def command_line(pid: int) -> list[str]:
    """``pid``'s command line, its words (empty if gone)."""
    try:
        return [
            w for w in (PROC / str(pid) / "cmdline").read_bytes().decode(errors="replace").split("\0") if w
        ]
    except OSError:
        return []


def child_pids(pid: int) -> list[int]:
    """The processes ``pid`` started that still run (its children)."""
    children: set[int] = set()
    try:
        tasks = os.listdir(PROC / str(pid) / "task")
    except OSError:
        return []
    for task in tasks:
        with contextlib.suppress(OSError, ValueError):
            children.update(
                int(c) for c in (PROC / str(pid) / "task" / task / "children").read_text().split()
            )
    return sorted(children)
