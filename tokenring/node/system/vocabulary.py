"""The system commands' vocabulary (seed §3.4.2): what each command carries in the token's
system data window, answer codes, program states, one issuer transaction and its steps."""

from __future__ import annotations

import enum
import logging
import random
import struct
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from tokenring import runtime
from tokenring.contract.protocol import Field, Protocol, default_protocol, fields_struct
from tokenring.errors import ProgramError, ProtocolError

if TYPE_CHECKING:
    from tokenring.node.node_os import NodeOS
    from tokenring.node.store import Installed, ProgramStore

log = logging.getLogger("tokenring.system")


#: the 8051's code space: a node accepts programs up to this many bytes unless told otherwise
DEFAULT_CAPACITY = 65536
NO_ACK_LIMIT = 10  # rounds a live target may leave a command unacknowledged
#: how long a command waits for a target that is live but skipped by the ring, from the first
#: skipped round after its last answer (a false exclusion on a loaded machine heals in a few
#: rounds); unacknowledged rounds meanwhile prove nothing, the token does not visit the target
EXCLUDED_WAIT_S = 3.0
LOST_LIMIT = 200  # times a command may vanish from the token (regeneration, sweep) per transaction
POLL_TIMEOUT_S = 15.0  # how long a target may answer PENDING (verify, install, start)
START_GRACE_S = 0.3  # a program that raises within this time of its start fails the start
ERROR_PARTS = 8  # an ARCNET_ERROR text is cut to this many 30-byte parts


@dataclass(frozen=True)
class WindowLayouts:
    """What the system commands carry in the 32-byte window, compiled from protocol.yaml's
    ``system.window`` (nothing here hard-codes an offset)."""

    CONFIG: struct.Struct  # ARCNET_GET_CONFIG answer
    BEGIN: struct.Struct  # ARCNET_DOWNLOAD_BEGIN request
    STAMP: struct.Struct  # ARCNET_SEND_CONFIG request
    NONCE: struct.Struct  # ARCNET_START_PROGRAM / STOP_PROGRAM request
    ERROR: struct.Struct  # ARCNET_ERROR request
    STATUS: struct.Struct  # ARCNET_GET_STATUS answer
    INDEX: struct.Struct  # the chunk index in front of an ARCNET_DOWNLOAD_DATA chunk

    @classmethod
    def of(cls, protocol: Protocol) -> WindowLayouts:
        window = protocol.system_window

        def layout(name: str, part: str) -> tuple[Field, ...]:
            try:
                return window[name][part]
            except KeyError:
                raise ProtocolError(
                    protocol.source, f"system.window.{name}.{part}", "missing (the system layer needs it)"
                ) from None

        return cls(
            CONFIG=fields_struct(layout("ARCNET_GET_CONFIG", "answer")),
            BEGIN=fields_struct(layout("ARCNET_DOWNLOAD_BEGIN", "request")),
            STAMP=fields_struct(layout("ARCNET_SEND_CONFIG", "request")),
            NONCE=fields_struct(layout("ARCNET_START_PROGRAM", "request")),
            ERROR=fields_struct(layout("ARCNET_ERROR", "request")),
            STATUS=fields_struct(layout("ARCNET_GET_STATUS", "answer")),
            INDEX=fields_struct(layout("ARCNET_DOWNLOAD_DATA", "request")[:1]),
        )


class Status(enum.IntEnum):
    """First byte of a target's answer."""

    OK = 0
    PENDING = 1
    REFUSED = 2
    NOT_DOWNLOADING = 3
    BAD_SEQUENCE = 4
    CORRUPT = 5
    LOAD_ERROR = 6
    NO_PROGRAM = 7
    START_FAILED = 8
    STORE_ERROR = 9
    UNKNOWN_COMMAND = 10


class State(enum.IntEnum):
    """A node's program state, as GET_CONFIG and GET_STATUS report it."""

    NONE = 0
    STOPPED = 1
    RUNNING = 2
    FAILED = 3
    SETTING_UP = 4  # started, its setup() has not returned (its run() has not begun)

    @property
    def runs(self) -> bool:
        """The program has been started and neither failed nor stopped (set up or not)."""
        return self in (State.RUNNING, State.SETTING_UP)


ENCODINGS = {0: "raw", 1: "zlib"}


def _text(raw: bytes) -> str:
    return raw.split(b"\0", 1)[0].decode("utf-8", "replace")


def _short(text: str, size: int) -> bytes:
    """``text`` in at most ``size`` bytes of UTF-8, cut at a character's boundary (a name)."""
    return text.encode("utf-8", "replace")[:size].decode("utf-8", "ignore").encode("utf-8")


ELLIPSIS = b"..."


def _clipped(text: str, size: int) -> bytes:
    """A message for a fixed text field of ``size`` bytes: whole if it fits, else cut at a word
    (or at least a character) and ended with ``...``, never mid-character or mid-word unseen.
    Where the field is too small, the full text goes elsewhere (an ARCNET_ERROR, the log)."""
    raw = text.encode("utf-8", "replace")
    if len(raw) <= size:
        return raw
    cut = _short(text, size - len(ELLIPSIS))
    space = cut.rfind(b" ")
    if space >= 2 * len(cut) // 3:  # a word boundary near the end: do not show half a word
        cut = cut[:space]
    return cut.rstrip(b" :,;") + ELLIPSIS


@dataclass(slots=True)
class Step:
    """One system command of a transaction."""

    target: int
    code: int
    payload: bytes = b""
    poll: bool = False  # resend while the target answers PENDING
    keep: bool = False  # keep the answer (the window after the round)


@dataclass
class Transaction:
    """Commands one issuer sends back to back, one per round, while the window stays saved."""

    steps: list[Step]
    what: str = ""
    index: int = 0
    retries: int = 0
    lost: int = 0
    resends: int = 0
    rounds: int = 0
    answers: dict[int, bytes] = field(default_factory=dict)
    status: Status | None = None
    error: str | None = None
    failed_step: int | None = None
    done: Any = field(default_factory=lambda: runtime.current().event())  # the runtime's event
    cancelled: bool = False
    started: float = 0.0
    finished: float = 0.0
    poll_deadline: float = 0.0
    excluded_since: float = 0.0
    epoch: int = -1

    @property
    def ok(self) -> bool:
        return self.done.is_set() and self.error is None

    def progress(self) -> dict[str, Any]:
        end = self.finished or runtime.current().monotonic()
        return {
            "what": self.what,
            "step": self.index,
            "steps": len(self.steps),
            "done": self.done.is_set(),
            "error": self.error,
            "status": self.status.name if self.status is not None else None,
            "failed_step": self.failed_step,
            "rounds": self.rounds,
            "resends": self.resends,
            "elapsed_s": (end - self.started) if self.started else 0.0,
        }


class SystemCommandError(ProgramError):
    """A system command failed; ``status`` is the target's answer if it gave one."""

    def __init__(self, message: str, status: Status | None = None, node: int | None = None) -> None:
        super().__init__(message)
        self.status = status
        self.node = node


# ---------------------------------------------------------------------------------------------
# receiver side state


@dataclass(slots=True)
class _Download:
    size: int
    transfer: int
    encoding: int
    chunk: int
    chunks: int
    buffer: bytearray
    next: int = 0


@dataclass(slots=True)
class _Job:
    key: bytes
    status: Status = Status.PENDING
    detail: str = ""


@dataclass
class SystemStats:
    """Counters of one node's system layer (control verb ``system``)."""

    commands_issued: int = 0
    commands_taken: int = 0
    resends: int = 0
    lost_commands: int = 0
    orphans_cleared: int = 0
    downloads_begun: int = 0
    chunks_received: int = 0
    chunk_repeats: int = 0
    bytes_received: int = 0
    downloads_verified: int = 0
    downloads_rejected: int = 0
    installs: int = 0
    starts: int = 0
    stops: int = 0
    errors_sent: int = 0
    errors_received: int = 0


def decode_config(answer: bytes, node_id: int, layouts: WindowLayouts | None = None) -> dict[str, Any]:
    """A GET_CONFIG answer as a dict (``state`` by name, ``sha256`` as 16 hex digits)."""
    layouts = layouts or WindowLayouts.of(default_protocol())
    _, state, stamp, size, digest, name = layouts.CONFIG.unpack(answer)
    return {
        "id": node_id,
        "name": _text(name),
        "state": State(state).name if state in State._value2member_map_ else str(state),
        "stamp_ms": stamp,
        "size": size,
        "sha256": digest.hex() if size else "",
    }


# ---------------------------------------------------------------------------------------------
# main's PC-link verbs


class SystemParts:
    """The state the issuer and receiver halves of :class:`~tokenring.node.system.layer.SystemLayer` share
    (set up by its ``__init__``), and the calls one half makes on the other."""

    os: NodeOS
    me: int  # this node's ID
    store: ProgramStore
    capacity: int
    starter: Callable[[type], None]
    stats: SystemStats
    # the token's header offsets and the system data window [w0, w1) of wsize bytes
    _o_issuer: int
    _o_target: int
    _o_code: int
    _o_length: int
    _o_ack: int
    _o_epoch: int
    _o_origin: int
    all_nodes: int
    w0: int
    wsize: int
    w1: int
    layouts: WindowLayouts
    chunk_size: int
    codes: dict[str, int]
    SCAN: int
    GET_CONFIG: int
    SEND_CONFIG: int
    DATA: int
    TERMINATED: int
    START_SYSTEM: int
    STOP_SYSTEM: int
    START_PROGRAM: int
    STOP_PROGRAM: int
    ERROR: int
    BEGIN: int
    GET_STATUS: int
    _receivers: dict[int, Callable[[bytearray], None]]
    # the issuer's
    _queue: deque[Transaction]
    _current: Transaction | None
    _rt: Any  # the runtime (tokenring.runtime): locks, queue, worker, clock
    _clock: Callable[[], float]
    _rng: random.Random
    _lock: Any
    _saved: bytes | None
    _rest: bool
    # the receiver's
    _download: _Download | None
    _verified: Installed | None
    _job: _Job | None
    installed: Installed | None
    _previous: Installed | None  # the program before the installed one, until it has started
    _running_digest: bytes | None
    _error_parts: dict[int, dict[int, bytes]]
    errors: deque[dict[str, Any]]
    _error_count: Iterator[int]
    corrupt_chunk: int | None
    _reported_program: Any
    _work: Any  # the runtime's simple queue of (action, args), None to stop
    _worker: Any
    _closing: bool

    def submit(self, steps: list[Step], what: str = "") -> Transaction:
        raise NotImplementedError
