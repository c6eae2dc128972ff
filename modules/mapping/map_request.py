"""The requester's side of GET_MAP: collect VECTOR_COUNTER n and then n VECTORs from the map module.

A module with its own command loop (main, lcd) feeds every received command to
:meth:`MapCollector.feed`; a module with nothing else to do can call :func:`request_map`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from tokenring.runtime import current as current_runtime

if TYPE_CHECKING:
    from tokenring import NodeOS


class MapCollector:
    """Assembles one GET_MAP answer (vectors in cm, in the map's order)."""

    def __init__(self) -> None:
        self.rt = current_runtime()  # the clock, lock and event: the process's, or a simulation's
        self.lock = self.rt.lock()
        self.expected: int | None = None
        self.vectors: list[tuple[int, int, int, int]] = []
        self.done = self.rt.event()
        self.active = False

    def begin(self) -> None:
        """Forget any earlier answer; call before sending GET_MAP."""
        with self.lock:
            self.expected = None
            self.vectors = []
            self.done.clear()
            self.active = True

    def feed(self, name: str, args: dict[str, Any]) -> bool:
        """Take a received command if it belongs to the answer; True if it did."""
        with self.lock:
            if not self.active:
                return False
            if name == "VECTOR_COUNTER":
                self.expected = int(args["count"])
                self.vectors = []
            elif name == "VECTOR" and self.expected is not None:
                self.vectors.append((args["x1"], args["y1"], args["x2"], args["y2"]))
            else:
                return False
            if self.expected is not None and len(self.vectors) >= self.expected:
                self.active = False
                self.done.set()
            return True

    def progress(self) -> tuple[int, int | None]:
        with self.lock:
            return len(self.vectors), self.expected

    def wait(self, timeout: float) -> list[tuple[int, int, int, int]] | None:
        """The whole map, or None if it did not arrive in time (waiting restarts while vectors flow)."""
        deadline = self.rt.monotonic() + timeout
        last = -1
        while not self.done.wait(0.05):
            received, _ = self.progress()
            if received != last:  # still streaming: a long map is not a timeout
                last = received
                deadline = self.rt.monotonic() + timeout
            if self.rt.monotonic() > deadline:
                with self.lock:
                    self.active = False
                return None
        with self.lock:
            return list(self.vectors)


def request_map(os: NodeOS, timeout: float = 5.0) -> list[tuple[int, int, int, int]] | None:
    """Send GET_MAP to the map module and receive the answer on this node's own inbox."""
    collector = MapCollector()
    collector.begin()
    if not os.deliver("map", "GET_MAP", timeout=timeout):
        return None
    clock = collector.rt.monotonic
    deadline = clock() + timeout
    while not collector.done.is_set():
        command = os.receive_command(timeout=0.1)
        if command is not None:
            collector.feed(command.name, command.args)
            deadline = clock() + timeout
        elif clock() > deadline or os.stopping:
            return None
    return collector.wait(0)
