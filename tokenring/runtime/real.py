"""The real runtime: the operating system's clock and threads, exactly as the ring used them
before it had a runtime (``time.monotonic``, ``threading``, ``queue``)."""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable
from typing import Any


class RealRuntime:
    """Wall-clock time and OS threads; every call is the standard library's own."""

    name = "real"
    simulated = False

    def monotonic(self) -> float:
        return time.monotonic()

    def time(self) -> float:
        return time.time()

    def sleep(self, seconds: float) -> None:
        time.sleep(max(0.0, seconds))

    def event(self) -> threading.Event:
        return threading.Event()

    def lock(self) -> threading.Lock:
        return threading.Lock()

    def condition(self, lock: Any = None) -> threading.Condition:
        return threading.Condition(lock)

    def queue(self, maxsize: int = 0) -> queue.Queue[Any]:
        return queue.Queue(maxsize)

    def spawn(self, target: Callable[[], Any], name: str, daemon: bool = True) -> threading.Thread:
        thread = threading.Thread(target=target, name=name, daemon=daemon)
        thread.start()
        return thread
