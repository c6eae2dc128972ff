"""Every error tokenring raises on purpose, in one tree.

    TokenRingError                 base: a message meant for a person, never a traceback
    ├── UsageError                 bad command-line input (unknown node, bad option value); exit 2
    ├── ProtocolError              protocol.yaml is unreadable or inconsistent; names file and entry
    ├── FrameError                 a frame on the wire is malformed (length, CRC, markers, IDs)
    ├── ChannelError               a user program misused a channel (unknown name, wrong kind, size)
    ├── ProgramError               a user program cannot be loaded or started
    └── TransportError             the transport below the ring failed (Zenoh, sockets)
        ├── TransportClosed        an operation on a transport that is already closed
        └── AddressInUse           a listen endpoint another process holds; exit 2

Backend exceptions are translated once, where they cross the transport seam
(``raise TransportError(...) from exc``), so callers above never see Zenoh's own types.
"""

from __future__ import annotations


class TokenRingError(Exception):
    """Base of all tokenring errors; ``str()`` is a complete message for the user."""

    exit_code = 1


class UsageError(TokenRingError):
    """The user asked for something that cannot be done as asked."""

    exit_code = 2


class ProtocolError(TokenRingError):
    """``protocol.yaml`` is malformed; the message names the file and the offending entry."""

    exit_code = 2

    def __init__(self, source: str, entry: str, problem: str) -> None:
        self.source = source
        self.entry = entry
        self.problem = problem
        where = f"{source}: {entry}" if entry else source
        super().__init__(f"{where}: {problem}")


class FrameError(TokenRingError):
    """A received frame cannot be accepted; ``reason`` is the counter it is filed under."""

    def __init__(self, reason: str, detail: str) -> None:
        self.reason = reason
        super().__init__(f"frame rejected ({reason}): {detail}")


class ChannelError(TokenRingError):
    """A user program used a channel in a way the protocol does not allow."""


class ProgramError(TokenRingError):
    """A user program could not be loaded, verified or started."""


class TransportError(TokenRingError):
    """The transport under the ring failed; the original exception is chained."""


class TransportClosed(TransportError):
    """The transport was used after it was closed."""


class AddressInUse(TransportError):
    """An endpoint to listen on is held by another process: the user's choice, so exit 2."""

    exit_code = 2
