"""The real runtime: the operating system's clock and threads, exactly as the ring used them
before it had a runtime (``time.monotonic``, ``threading``, ``queue``)."""

from __future__ import annotations

import queue
import queue as _queue
import random
import threading
import time
from collections.abc import Callable, Iterable
from typing import Any


class RealRuntime:
    """Wall-clock time and OS threads; every call is the standard library's own.

    The clocks and ``current_thread`` are the standard library's functions themselves, not
    wrappers: code that binds ``rt.monotonic`` once pays nothing per call for the runtime."""

    name = "real"
    simulated = False

    monotonic = staticmethod(time.monotonic)
    time = staticmethod(time.time)
    current_thread = staticmethod(threading.current_thread)

    def sleep(self, seconds: float) -> None:
        time.sleep(max(0.0, seconds))

    def event(self) -> threading.Event:
        return threading.Event()

    def lock(self) -> threading.Lock:
        return threading.Lock()

    def rlock(self) -> Any:
        return threading.RLock()

    def condition(self, lock: Any = None) -> threading.Condition:
        return threading.Condition(lock)

    def queue(self, maxsize: int = 0) -> queue.Queue[Any]:
        return queue.Queue(maxsize)

    def simple_queue(self) -> _queue.SimpleQueue[Any]:
        """An unbounded FIFO without ``task_done`` (C-fast in the real runtime)."""
        return queue.SimpleQueue()

    def spawn(self, target: Callable[[], Any], name: str, daemon: bool = True) -> threading.Thread:
        thread = threading.Thread(target=target, name=name, daemon=daemon)
        thread.start()
        return thread

    def timer(
        self, interval: float, function: Callable[..., Any], args: Iterable[Any] = ()
    ) -> threading.Timer:
        """A :class:`threading.Timer`, not started yet (``start``, ``cancel``, ``daemon``)."""
        return threading.Timer(interval, function, args=list(args))

    def rng(self) -> random.Random:
        """A random generator seeded from the OS: what must differ from process to process."""
        return random.Random()
