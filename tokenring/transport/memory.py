"""An in-process transport: several nodes in one Python process, for fast ring-logic tests.

Each node gets its own delivery thread fed by a queue, so handlers run asynchronously as they
do over Zenoh. A :class:`MemoryHub` is the shared medium; it can also emulate a crashed node
(:meth:`MemoryHub.crash`) or a hung one (:meth:`MemoryHub.freeze`). Threads, queues and locks
come from the runtime in force when the hub and a transport are made (:mod:`tokenring.runtime`):
in a simulation each delivery thread is a simulated task, and frames still reach a node's
handler in that node's own task.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from tokenring import runtime
from tokenring.transport.base import (
    FrameHandler,
    FrameSender,
    MembershipHandler,
    MessageHandler,
    Transport,
)

if TYPE_CHECKING:
    import hashlib

_STOP = object()
_HASH_CHUNK = 128  # pieces (a frame's sender and receiver, the frame) hashed at once: 64 frames


class MemoryHub:
    """The shared medium of a set of :class:`MemoryTransport` nodes."""

    def __init__(self) -> None:
        self._rt = runtime.current()
        self._lock = self._rt.lock()
        self._nodes: dict[int, MemoryTransport] = {}
        self._live: set[int] = set()
        self.frames_delivered = 0
        self.wire: list[tuple[int, int, bytes]] = []  # (sender, receiver, frame) when tapping
        self.tapping = False
        self._digest: hashlib._Hash | None = None
        # what the digest has yet to take in: the frames go into it a chunk at a time (hashlib's
        # per-call cost was a third of hashing a frame); the hash is the same, SHA-256 streams
        self._unhashed: list[bytes] = []
        self._groups: list[set[int]] | None = None
        self._drop_frames = 0
        #: told (sender, receiver, frame) of every frame put on the wire, delivered or not, as a
        #: subscriber to the ring's token keys sees it (a simulation's capture)
        self.on_frame: Callable[[int, int, bytes], None] | None = None

    def hash_frames(self) -> None:
        """Start hashing the delivered frames into :attr:`digest` (from the next one on)."""
        import hashlib  # here: OpenSSL is megabytes a process that never hashes need not load

        self._digest = hashlib.sha256()
        self._unhashed.clear()

    @property
    def digest(self) -> hashlib._Hash | None:
        """A running SHA-256 of every frame the hub delivers, each after its sender and receiver
        (a simulation's run is repeatable when two runs end with the same digest); None: off."""
        if self._unhashed and self._digest is not None:
            self._digest.update(b"".join(self._unhashed))
            self._unhashed.clear()
        return self._digest

    def attach(self, transport: MemoryTransport) -> set[int]:
        with self._lock:
            self._nodes[transport.node_id] = transport
            return set(self._live)

    def detach(self, node_id: int, transport: MemoryTransport | None = None) -> None:
        """The node leaves the hub (``transport``: only if it is still the one under that ID, not
        a new process's that took its place)."""
        with self._lock:
            if transport is not None and self._nodes.get(node_id) is not transport:
                return
            self._nodes.pop(node_id, None)
            was_live = node_id in self._live
            self._live.discard(node_id)
            targets = list(self._nodes.values())
        if was_live:
            for node in targets:
                node._deliver(("member", node_id, False))

    def set_live(self, node_id: int, live: bool) -> None:
        with self._lock:
            if live:
                self._live.add(node_id)
            else:
                self._live.discard(node_id)
            targets = list(self._nodes.values())
        for node in targets:
            node._deliver(("member", node_id, live))

    def _separated(self, a: int, b: int) -> bool:
        if self._groups is None:
            return False
        return not any(a in group and b in group for group in self._groups)

    def send(self, sender: int, did: int, item: tuple) -> None:
        # once per frame in a simulation: the checks of _separated and _deliver are inlined
        frame = item[0] == "frame"
        if frame and self.on_frame is not None:
            self.on_frame(sender, did, item[1])
        with self._lock:
            node = self._nodes.get(did)
            if self._groups is not None and self._separated(sender, did):
                return
            if frame:
                if self.tapping:
                    self.wire.append((sender, did, item[1]))
                if self._drop_frames:
                    self._drop_frames -= 1
                    return
        if node is not None:
            if frame:
                self.frames_delivered += 1
                if self._digest is not None:
                    unhashed = self._unhashed
                    unhashed.append(bytes((sender, did)))
                    unhashed.append(item[1])
                    if len(unhashed) >= _HASH_CHUNK:
                        self._digest.update(b"".join(unhashed))
                        unhashed.clear()
            if not node._dead:
                node._queue.put(item)

    def broadcast(self, sender: int, item: tuple) -> None:
        with self._lock:
            targets = [n for i, n in self._nodes.items() if not self._separated(sender, i)]
        for node in targets:
            node._deliver(item)

    def partition(self, *groups: set[int]) -> None:
        """Frames and messages no longer cross between the groups (liveliness still does)."""
        with self._lock:
            self._groups = [set(g) for g in groups]

    def heal(self) -> None:
        with self._lock:
            self._groups = None

    def drop_frames(self, count: int = 1) -> None:
        """Lose the next ``count`` frames on the wire."""
        with self._lock:
            self._drop_frames += count

    def crash(self, node_id: int) -> None:
        """The node vanishes at once: it receives nothing more and its liveliness drops."""
        with self._lock:
            node = self._nodes.get(node_id)
        if node is not None:
            node._dead = True
        self.detach(node_id)

    def freeze(self, node_id: int, frozen: bool = True) -> None:
        """Like SIGSTOP/SIGCONT: the node stays live but handles nothing until thawed."""
        with self._lock:
            node = self._nodes.get(node_id)
        if node is not None:
            if frozen:
                node._thawed.clear()
            else:
                node._thawed.set()


class MemoryTransport(Transport):
    """A node on a :class:`MemoryHub`."""

    kind = "memory"

    def __init__(self, hub: MemoryHub, ring: str, node_id: int, frame_size: int = 514) -> None:
        super().__init__(ring, node_id, frame_size)
        self.hub = hub
        self._queue = self._rt.simple_queue()
        self._thread: Any = None
        self._thawed = self._rt.event()
        self._thawed.set()
        self._dead = False
        self._handlers: tuple[FrameHandler, MessageHandler, MembershipHandler] | None = None

    def _deliver(self, item: tuple) -> None:
        if not self._dead:
            self._queue.put(item)

    def _run(self) -> None:
        assert self._handlers is not None
        on_frame, on_message, on_membership = self._handlers
        dispatch: dict[str, Callable[..., None]] = {
            "frame": on_frame,
            "message": on_message,
            "member": on_membership,
        }
        while True:
            item = self._queue.get()
            if item is _STOP:
                return
            self._thawed.wait()
            if self._dead:
                return
            dispatch[item[0]](*item[1:])

    def _open(
        self, on_frame: FrameHandler, on_message: MessageHandler, on_membership: MembershipHandler
    ) -> set[int]:
        self._handlers = (on_frame, on_message, on_membership)
        members = self.hub.attach(self)
        self._thread = self._rt.spawn(self._run, f"memory-transport-{self.node_id}")
        members.discard(self.node_id)
        return members

    def _sender(self, did: int) -> FrameSender:
        return functools.partial(self._send_frame, did)  # no Python frame of its own per send

    def _send_frame(self, did: int, frame: bytes | bytearray) -> None:
        self._thawed.wait()  # a stopped process sends nothing: every thread blocks, like SIGSTOP
        if not self._dead:
            self.hub.send(self.node_id, did, ("frame", bytes(frame)))

    def _send_message(self, did: int, payload: bytes) -> None:
        self._thawed.wait()
        if not self._dead:
            self.hub.send(self.node_id, did, ("message", payload))

    def _broadcast(self, payload: bytes) -> None:
        self._thawed.wait()
        if not self._dead:
            self.hub.broadcast(self.node_id, ("message", payload))

    def _announce(self) -> None:
        self.hub.set_live(self.node_id, True)

    def _withdraw(self) -> None:
        self.hub.set_live(self.node_id, False)

    def _close(self) -> None:
        self.hub.detach(self.node_id, self)
        self._thawed.set()
        self._queue.put(_STOP)
        if self._thread is not None and self._thread is not self._rt.current_thread():
            self._thread.join(timeout=2.0)
