"""The boundary between the ring and whatever carries its bytes.

A :class:`Transport` moves three things for one node: frames to a successor, small unicast
messages (pass acknowledgements) and ring-wide broadcasts (ring events), and it reports
membership (who is live). The public methods own the checks, the counting and the translation
of backend errors; a backend implements only the ``_underscore`` methods. Backends:
``zenoh`` (the real one), ``memory`` (in-process, for fast tests of the ring logic).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable

from tokenring import runtime
from tokenring.errors import FrameError, TokenRingError, TransportClosed, TransportError

FrameHandler = Callable[[bytes], None]
FrameSender = Callable[[bytes | bytearray], None]
MessageHandler = Callable[[bytes], None]
MembershipHandler = Callable[[int, bool], None]


class Transport(ABC):
    """One node's view of the medium; subclasses implement the ``_`` methods."""

    kind = "abstract"

    def __init__(self, ring: str, node_id: int, frame_size: int = 514) -> None:
        self.ring = ring
        self.node_id = node_id
        self.frame_size = frame_size
        self._closed = False
        self._opened = False
        #: the runtime in force when the transport was made: its locks and threads are this one's
        self._rt = runtime.current()
        self._lock = self._rt.lock()
        #: the IDs this node passes the token among (set by the node before :meth:`open`); a
        #: backend whose nodes see only part of the network tells joiners this
        self.active_view: Callable[[], Iterable[int]] | None = None

    # -- life cycle ---------------------------------------------------------------------------
    def open(
        self,
        on_frame: FrameHandler,
        on_message: MessageHandler,
        on_membership: MembershipHandler,
    ) -> set[int]:
        """Start receiving; returns the IDs live right now (this node not yet among them)."""
        if self._closed:
            raise TransportClosed("transport already closed")
        try:
            members = self._open(on_frame, on_message, on_membership)
        except TokenRingError:
            raise
        except Exception as exc:
            raise TransportError(f"{self.kind}: cannot open for node {self.node_id}: {exc}") from exc
        self._opened = True
        return members

    def announce(self) -> None:
        """Tell every node this one is live (its liveliness token)."""
        self._guard(self._announce, "announce")

    def withdraw(self) -> None:
        """Stop being listed as live (a clean leave); frames keep arriving until close."""
        self._guard(self._withdraw, "withdraw")

    def close(self) -> None:
        """Release everything; safe to call twice."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        try:
            self._close()
        except Exception as exc:
            raise TransportError(f"{self.kind}: close failed: {exc}") from exc

    @property
    def closed(self) -> bool:
        return self._closed

    # -- traffic ------------------------------------------------------------------------------
    def send_frame(self, did: int, frame: bytes | bytearray) -> None:
        """Send a sealed frame to node ``did``."""
        if self._closed:
            raise TransportClosed("send on a closed transport")
        if len(frame) != self.frame_size:
            raise FrameError("length", f"refusing to send {len(frame)} bytes, frames are {self.frame_size}")
        try:
            self._send_frame(did, frame)
        except Exception as exc:
            raise TransportError(f"{self.kind}: sending the token to node {did} failed: {exc}") from exc

    def sender(self, did: int) -> FrameSender:
        """The token path's fast lane: a callable sending frames to ``did`` without re-checking.

        The node OS only ever hands it sealed, full-size frames; exceptions it raises are the
        backend's and must be translated by the caller (:meth:`translate`).
        """
        if self._closed:
            raise TransportClosed("send on a closed transport")
        try:
            return self._sender(did)
        except Exception as exc:
            raise TransportError(f"{self.kind}: no path to node {did}: {exc}") from exc

    def translate(self, did: int, exc: BaseException) -> TransportError:
        """A backend exception raised by a :meth:`sender` callable, as a TransportError."""
        if isinstance(exc, TransportError):
            return exc
        error = TransportError(f"{self.kind}: sending the token to node {did} failed: {exc}")
        error.__cause__ = exc
        return error

    def send_message(self, did: int, payload: bytes) -> None:
        """A small unicast message (pass acknowledgement) to node ``did``."""
        self._guard(lambda: self._send_message(did, payload), f"message to {did}")

    def broadcast(self, payload: bytes) -> None:
        """A ring event to every node (including this one)."""
        self._guard(lambda: self._broadcast(payload), "broadcast")

    def prepare(self, did: int) -> None:
        """Warm up the path to ``did`` before the token needs it (optional for backends)."""
        if not self._closed:
            self._guard(lambda: self._prepare(did), f"prepare {did}")

    def _guard(self, action: Callable[[], None], what: str) -> None:
        if self._closed:
            raise TransportClosed(f"{what} on a closed transport")
        try:
            action()
        except TokenRingError:
            raise
        except Exception as exc:
            raise TransportError(f"{self.kind}: {what} failed: {exc}") from exc

    # -- backend ------------------------------------------------------------------------------
    @abstractmethod
    def _open(
        self, on_frame: FrameHandler, on_message: MessageHandler, on_membership: MembershipHandler
    ) -> set[int]: ...

    @abstractmethod
    def _send_frame(self, did: int, frame: bytes | bytearray) -> None: ...

    def _sender(self, did: int) -> FrameSender:
        return lambda frame: self._send_frame(did, frame)

    @abstractmethod
    def _send_message(self, did: int, payload: bytes) -> None: ...

    @abstractmethod
    def _broadcast(self, payload: bytes) -> None: ...

    @abstractmethod
    def _announce(self) -> None: ...

    @abstractmethod
    def _withdraw(self) -> None: ...

    @abstractmethod
    def _close(self) -> None: ...

    def _prepare(self, did: int) -> None:  # noqa: B027 - optional hook
        pass
