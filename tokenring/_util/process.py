"""A process's lifetime: its stop flag, a signal-proof wait for it, dying with the parent."""

from __future__ import annotations

import contextlib
import ctypes
import select
import signal
import socket
import threading
import time

#: how long a wait for a stop sleeps at most off the main thread, where no signal's byte wakes it
SIGNAL_CHECK_S = 0.2


class StopEvent(threading.Event):
    """A process's stop flag that :func:`wait_for_stop` sleeps on without polling.

    Setting it, from any thread or a signal handler, also writes a byte to a socket the waiting
    main thread selects on; the same socket is the signal module's wake-up fd, so a signal the
    kernel hands to another thread (one of Zenoh's) wakes the main thread at once too.
    """

    def __init__(self) -> None:
        super().__init__()
        self.wake_reader, self._wake_writer = socket.socketpair()
        self.wake_reader.setblocking(False)
        self._wake_writer.setblocking(False)

    def set(self) -> None:
        """Set the flag and wake the waiter."""
        super().set()
        # a full buffer holds wake-ups already; a closing process may have shut the socket
        with contextlib.suppress(OSError):
            self._wake_writer.send(b"\0")

    @property
    def wake_fd(self) -> int:
        """The socket a signal's C handler writes to (``signal.set_wakeup_fd``)."""
        return self._wake_writer.fileno()


def stop_on_signals(*signums: int) -> StopEvent:
    """A stop flag that these signals (default SIGTERM and SIGINT) set: a service process's
    clean end, waited for with :func:`wait_for_stop` on the main thread."""
    stop = StopEvent()

    def on_signal(_signum: int, _frame: object) -> None:
        stop.set()

    for signum in signums or (signal.SIGTERM, signal.SIGINT):
        signal.signal(signum, on_signal)
    return stop


def wait_for_stop(stop: StopEvent, duration: float | None = None) -> bool:
    """Wait until ``stop`` is set (a signal handler sets it) or ``duration`` is up; True if
    stopped.

    The kernel may hand SIGTERM to any thread (Zenoh's Rust ones too), and then only wakes that
    one: a main thread asleep on an endless wait never runs its Python handler. The main thread
    sleeps in ``select`` on the stop flag's socket, which the signal's C handler writes to
    whichever thread took it, so an idle node never wakes; another thread (which cannot own the
    wake-up fd) waits in slices of :data:`SIGNAL_CHECK_S`.
    """
    deadline = None if duration is None else time.monotonic() + duration
    on_main = threading.current_thread() is threading.main_thread()
    previous = signal.set_wakeup_fd(stop.wake_fd, warn_on_full_buffer=False) if on_main else None
    try:
        while not stop.is_set():
            remaining = None if deadline is None else deadline - time.monotonic()
            if remaining is not None and remaining <= 0:
                return False
            if on_main:
                # the handler of a signal taken by another thread runs once this thread is back
                # in bytecode, right after select returns; its stop.set() then ends the loop
                select.select([stop.wake_reader], [], [], remaining)
                _drain(stop.wake_reader)
            else:
                stop.wait(SIGNAL_CHECK_S if remaining is None else min(SIGNAL_CHECK_S, remaining))
        return True
    finally:
        if previous is not None:
            signal.set_wakeup_fd(previous)


def _drain(reader: socket.socket) -> None:
    with contextlib.suppress(BlockingIOError, InterruptedError):
        while reader.recv(64):
            pass


def die_with_parent() -> None:  # pragma: no cover - runs in the child between fork and exec
    """``preexec_fn`` of a child process: the kernel kills it when its parent dies, even by SIGKILL
    — and when the *thread* that started it ends, so start children only from threads that
    outlive them."""
    libc = ctypes.CDLL("libc.so.6", use_errno=True)
    libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
