"""The launcher's plumbing: its children's output, prefixed and never blocking, their exits,
watched through pidfds so that supervising 255 children costs no polling, and the end of what
each child started (every child leads a process group of its own)."""

from __future__ import annotations

import contextlib
import os
import queue
import selectors
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Collection
from typing import IO, Any

from tokenring.contract.faults import CRASH_EXIT_CODE

#: how often a group being ended is looked at in /proc (only while one is)
GROUP_CHECK_S = 0.05
#: a child gets this long after SIGTERM before SIGKILL, and the kernel this long to reap it
STOP_TIMEOUT_S = 1.5
KILL_REAP_S = 10.0
#: ``--respawn`` starts a dead node again this long after its exit (systemd's RestartSec default):
#: the ring heals around it first, instead of sharing two cores with a booting interpreter
RESPAWN_DELAY_S = 0.1


def describe_exit(code: int | None) -> str:
    """'exited with code 3', 'killed by SIGKILL', 'crashed on purpose (fault)'."""
    if code is None:
        return "still running"
    if code == CRASH_EXIT_CODE:
        return f"crashed on purpose (crash fault, exit code {code})"
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exited with code {code}"


class PrefixedOutput:
    """Every child's output lines, and the launcher's own, each prefixed with its name.

    Lines go through a bounded queue to one writer thread: if whoever reads the output stalls
    (a paused pager, an unread pipe), lines are dropped and counted — a stalled log must not
    stall the nodes writing it, and so the ring."""

    def __init__(self, output: IO[str], width: int) -> None:
        self.output = output
        self.width = max(width, 4)
        self._lines: queue.Queue[str | None] = queue.Queue(maxsize=20000)
        self._dropped = 0
        self._selector = selectors.DefaultSelector()
        self._selector_lock = threading.Lock()
        self._reader: threading.Thread | None = None
        self._writer = threading.Thread(target=self._write, name="launcher-writer", daemon=True)
        self._writer.start()

    def say(self, text: str, name: str = "up") -> None:
        """Queue one prefixed line; never blocks."""
        try:
            self._lines.put_nowait(f"{name:>{self.width}} | {text}\n")
        except queue.Full:
            self._dropped += 1

    def divert(self, output: IO[str]) -> IO[str]:
        """Write the lines to ``output`` from now on (a program that takes the terminal); returns
        where they went before."""
        self.flush()
        previous, self.output = self.output, output
        return previous

    def watch(self, stream: IO[str], name: str, relay: Callable[[str], None] | None = None) -> None:
        """Copy ``stream``'s lines under ``name`` until it closes; or hand each to ``relay``
        (a line that carries a prefix of its own: another host's share)."""
        with self._selector_lock:
            self._selector.register(stream, selectors.EVENT_READ, (name, relay))

    def start_reading(self, stopped: threading.Event) -> None:
        """Start copying the watched streams; the reader ends once ``stopped`` is set and every
        stream has closed."""
        self._reader = threading.Thread(
            target=self._read, args=(stopped,), name="launcher-output", daemon=True
        )
        self._reader.start()

    def join_reader(self, timeout: float = 1.0) -> None:
        if self._reader is not None:
            self._reader.join(timeout=timeout)

    def flush(self, timeout: float = 1.0) -> None:
        """Wait until the queued lines are written (for a clean end of the run)."""
        deadline = time.monotonic() + timeout
        while not self._lines.empty() and time.monotonic() < deadline:
            time.sleep(0.01)
        with contextlib.suppress(OSError, ValueError):
            self.output.flush()

    def _write(self) -> None:
        while True:
            line = self._lines.get()
            if line is None:
                return
            try:
                if self._dropped:
                    dropped, self._dropped = self._dropped, 0
                    self.output.write(
                        f"{'up':>{self.width}} | ({dropped} log lines dropped: output too slow)\n"
                    )
                self.output.write(line)
                if self._lines.empty():
                    self.output.flush()
            except (OSError, ValueError):
                pass  # the output went away; the ring goes on

    def _read(self, stopped: threading.Event) -> None:
        while True:
            with self._selector_lock:
                watching = bool(self._selector.get_map())
            if not watching:
                if stopped.is_set():
                    return
                time.sleep(0.05)
                continue
            for key, _ in self._selector.select(timeout=0.1):
                stream, (name, relay) = key.fileobj, key.data
                line = stream.readline()  # type: ignore[union-attr]
                if line:
                    if relay is not None:
                        relay(line.rstrip("\n"))
                    else:
                        self.say(line.rstrip("\n"), name)
                    continue
                with self._selector_lock, contextlib.suppress(KeyError, ValueError):
                    self._selector.unregister(stream)


class ExitWatch:
    """Children's exits as readable pidfds (Linux ≥ 5.3), plus a pipe that wakes the waiter.

    ``works`` turns False where pidfds are missing: the supervisor then polls instead."""

    def __init__(self) -> None:
        self._selector = selectors.DefaultSelector()
        self._lock = threading.Lock()  # registering (boot waves) against closing (stop)
        self._wake_r, self._wake_w = os.pipe()
        self._selector.register(self._wake_r, selectors.EVENT_READ, None)
        self.works = True

    def add(self, pid: int, data: Any) -> None:
        """Watch process ``pid``; its exit comes back from :meth:`wait` as ``data``."""
        try:
            pidfd = os.pidfd_open(pid)
        except (AttributeError, OSError):
            self.works = False
            return
        with self._lock:
            if self._selector.get_map() is None:  # closed meanwhile
                os.close(pidfd)
                return
            self._selector.register(pidfd, selectors.EVENT_READ, data)

    def wait(self, timeout: float) -> list[Any]:
        """The data of the children that exited within ``timeout`` (empty on a wake)."""
        ready = self._selector.select(timeout)
        exited = []
        with self._lock:
            for key, _ in ready:
                if key.data is not None:  # a child exited (else we were woken)
                    self._selector.unregister(key.fileobj)
                    os.close(key.fd)
                    exited.append(key.data)
        return exited

    def wake(self) -> None:
        """Wake whoever waits (idempotent; harmless once closed)."""
        if self._wake_w >= 0:
            with contextlib.suppress(OSError):
                os.write(self._wake_w, b"x")

    def close_reading(self) -> None:
        """Close the pidfds and the wake pipe's read end (the waiter's side)."""
        with self._lock:
            for key in list((self._selector.get_map() or {}).values()):
                self._selector.unregister(key.fileobj)
                os.close(key.fd)
            self._selector.close()

    def close_waking(self) -> None:
        """Close the wake pipe's write end (once the waiter has ended)."""
        if self._wake_w >= 0:
            with contextlib.suppress(OSError):
                os.close(self._wake_w)
            self._wake_w = -1


def live_group_members(pgids: Collection[int]) -> dict[int, list[int]]:
    """The processes (zombies not counted) in each of these process groups, from ``/proc``."""
    wanted = set(pgids)
    members: dict[int, list[int]] = {}
    if not wanted:
        return members
    with contextlib.suppress(OSError):
        for entry in os.scandir("/proc"):
            if not entry.name.isdigit():
                continue
            try:
                with open(f"/proc/{entry.name}/stat", "rb") as stat:
                    fields = stat.read().rsplit(b")", 1)[1].split()
            except (OSError, IndexError):
                continue  # gone meanwhile
            if len(fields) > 2 and fields[0] != b"Z" and int(fields[2]) in wanted:
                members.setdefault(int(fields[2]), []).append(int(entry.name))
    return members


#: the keeper's program (no site, no tokenring: it starts in milliseconds): ``+PGID`` and
#: ``-PGID`` lines hold and release a group; at the end of its input — the launcher exited, even
#: by SIGKILL — it SIGKILLs every group it still holds
KEEPER_PROGRAM = """
import os, signal, sys
signal.signal(signal.SIGINT, signal.SIG_IGN)
signal.signal(signal.SIGTERM, signal.SIG_IGN)
held = set()
for line in sys.stdin:
    (held.add if line[0] == "+" else held.discard)(int(line[1:]))
for pgid in held:
    try:
        os.killpg(pgid, signal.SIGKILL)
    except OSError:
        pass
"""


class GroupKeeper:
    """A small process that outlives a killed launcher to end its children's process groups.

    A node's parent-death signal kills the node with its launcher, but not what the node's
    program started: that lives on in the node's group. The keeper holds the launcher's groups
    over a pipe; when the pipe closes it kills those the launcher did not release. It leads a
    group of its own, out of the terminal's Ctrl-C and Ctrl-Z."""

    def __init__(self) -> None:
        self._process: subprocess.Popen[str] | None = None
        self._lock = threading.Lock()
        self._closed = False
        self.failed: str | None = None  # why the keeper is gone, once it is

    def hold(self, pgid: int) -> None:
        """Kill group ``pgid`` if the launcher dies before it releases it."""
        self._send(f"+{pgid}\n")

    def release(self, pgid: int) -> None:
        """Group ``pgid`` is gone: its number may be reused, the keeper must forget it."""
        self._send(f"-{pgid}\n")

    def close(self) -> None:
        """Release everything and let the keeper exit (the launcher ended its groups itself)."""
        with self._lock:
            process, self._process = self._process, None
            self._closed = True
        if process is None or process.stdin is None:
            return
        with contextlib.suppress(OSError):
            process.stdin.close()  # at its end of input it kills what it still holds: nothing
        with contextlib.suppress(subprocess.TimeoutExpired):
            process.wait(5.0)

    def _send(self, line: str) -> None:
        with self._lock:
            if self._closed or self.failed is not None:
                return
            try:
                if self._process is None:
                    self._process = subprocess.Popen(
                        [sys.executable, "-I", "-S", "-c", KEEPER_PROGRAM],
                        stdin=subprocess.PIPE,
                        text=True,
                        process_group=0,
                    )
                assert self._process.stdin is not None
                self._process.stdin.write(line)
                self._process.stdin.flush()
            except OSError as exc:
                self.failed = (
                    f"the process-group keeper is gone ({exc}): a killed launcher may leave processes"
                )


class GroupEnder:
    """Ends what is left of a child's process group once the child (its leader) has exited: a
    node's program and whatever it started end with the node. SIGTERM at once, SIGKILL to what
    still lives ``grace`` seconds later (as systemd stops what is left of a unit). Each group is
    also held by a :class:`GroupKeeper` until it is gone, for the launcher that is killed."""

    def __init__(self, grace: float) -> None:
        self.grace = grace
        self.keeper = GroupKeeper()
        self._due: dict[int, float] = {}  # process group -> when what is left of it is killed
        self._killed: set[int] = set()  # groups that were sent SIGKILL and may not be gone yet
        self._changed = threading.Condition()
        self._thread: threading.Thread | None = None

    def adopt(self, pgid: int) -> None:
        """A child started, leading group ``pgid``: it ends with the launcher, however that ends."""
        self.keeper.hold(pgid)

    def end(self, pgid: int) -> None:
        """SIGTERM to group ``pgid`` (its leader exited); SIGKILL ``grace`` seconds later."""
        try:
            os.killpg(pgid, signal.SIGTERM)
        except (ProcessLookupError, PermissionError):
            self.keeper.release(pgid)
            return  # nothing is left of it
        with self._changed:
            self._due.setdefault(pgid, time.monotonic() + self.grace)
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="launcher-groups", daemon=True)
                self._thread.start()
            self._changed.notify_all()

    def finish(self, timeout: float) -> list[int]:
        """Wait (at most ``timeout`` past the last group's SIGKILL) until every group handed over
        is gone; returns the PIDs still alive then (none, unless the kernel is slow)."""
        with self._changed:
            while self._due:
                self._changed.wait(GROUP_CHECK_S)
                self._kill_due()
        deadline = time.monotonic() + timeout
        while True:
            with self._changed:
                self._kill_due()
                left = [pid for pids in live_group_members(self._killed).values() for pid in pids]
            if not left or time.monotonic() >= deadline:
                return left
            time.sleep(GROUP_CHECK_S)

    def close(self) -> None:
        """Every group has been ended: the keeper may go."""
        self.keeper.close()

    def _run(self) -> None:
        with self._changed:
            while True:
                self._changed.wait(GROUP_CHECK_S if self._due or self._killed else None)
                self._kill_due()

    def _kill_due(self) -> None:
        """(Under the lock.) Forget (and release) the groups that are gone; SIGKILL the ones that
        are due."""
        if not self._due and not self._killed:
            return
        alive = live_group_members(set(self._due) | self._killed)
        for pgid in [g for g in self._killed if g not in alive]:
            self._killed.discard(pgid)
            self.keeper.release(pgid)
        now = time.monotonic()
        for pgid, due in list(self._due.items()):
            if pgid not in alive:
                del self._due[pgid]
                self.keeper.release(pgid)
            elif now >= due:
                with contextlib.suppress(ProcessLookupError, PermissionError):
                    os.killpg(pgid, signal.SIGKILL)
                del self._due[pgid]
                self._killed.add(pgid)
        self._changed.notify_all()
