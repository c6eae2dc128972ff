"""System commands: the seed's OS commands in the token, and program download over the ring.

Every node runs one :class:`SystemLayer`, installed as its ``NodeOS.system_handler``. A system
command lives in the token's header bytes ``syscmd_issuer``, ``syscmd_target``, ``syscmd_code``,
``syscmd_length``, ``syscmd_ack`` and the 32-byte system data window (``token.system_data``),
all from ``protocol.yaml``. While any node's command is in the token every node pauses its user
channels (absolute priority, seed §3.4.2); the issuer saves the window (which overlaps user
channels) before writing and restores it when it is done.

One command per token round: the issuer writes it, every node the command is for takes it as
the token passes and writes the acknowledge byte (its ID), and when the token is back the
issuer reads the answer and writes the next command of the same transaction (the window stays
saved) or restores the window and clears the command. After every transaction it leaves one
round free, so another node's command (an ``ARCNET_ERROR``) is not starved by a long download.

Wire format inside the window — defined in protocol.yaml (``system.window``) and compiled into
:class:`WindowLayouts`; summarised here (all little-endian; ``A`` marks what the target writes
back, whose first byte is always a :class:`Status` for single-target commands):

=========================  =====================================================================
command (target)           window
=========================  =====================================================================
ARCNET_SCAN (all)          256-bit membership bitmap; every node sets bit ``ID`` (byte ID>>3)
ARCNET_GET_CONFIG          A: status u8, state u8, time stamp u64 (ms since 1970), size u32,
                           sha256[:8], name str[10]
ARCNET_SEND_CONFIG         time stamp u64, sha256[:8]: install the verified download under this
                           stamp (or just re-stamp the installed program with that digest)
ARCNET_DOWNLOAD_BEGIN      source size u32, transfer size u32, encoding u8 (0 raw, 1 zlib),
                           chunk size u8; A: OK or REFUSED (larger than the node accepts)
ARCNET_DOWNLOAD_DATA       chunk index u16, up to 30 bytes of the transfer
ARCNET_DOWNLOAD_TERMINATED sha256 of the source (32 bytes): verify and compile the download
ARCNET_START_SYSTEM (all)  bitmap of the nodes that took it; each starts its program if stopped
ARCNET_STOP_SYSTEM (all)   bitmap; each stops its program
ARCNET_START_PROGRAM       nonce u32: start the installed program (unless it already runs)
ARCNET_STOP_PROGRAM        nonce u32: stop the program
ARCNET_ERROR (to master)   part u8 (bit 7: last part), about u8 (a command code, 0 = the running
                           program), 30 bytes of UTF-8 text: a traceback's last line
ARCNET_GET_STATUS          A: status u8, state u8, runs-installed u8, last error str[29]
=========================  =====================================================================

Commands with slow effects (verify, install, start) are polled: the target queues the work on
its worker thread, answers ``PENDING``, and answers the final status when the issuer resends the
very same command on the next round. Everything a target does in the token handler is a few
byte copies; hashing, compiling, writing the store and starting programs happen off that path.

Idempotence: a lost or regenerated token can replay a command. The issuer trusts an answer only
if the token still carries the epoch it wrote the command in, and resends otherwise; targets
treat a repeated chunk, a repeated poll and a start of what already runs as no-ops.

The program store ("battery-backed RAM") keeps each node's installed program and time stamp in a
directory (``--store``, ``$TOKENRING_STORE``, default ``~/.local/state/tokenring``), under
``<ring>/<node name>/``; see :class:`ProgramStore`.
"""

from __future__ import annotations

import contextlib
import enum
import hashlib
import itertools
import json
import logging
import os
import queue
import random
import shutil
import struct
import threading
import time
import zlib
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tokenring.errors import ProgramError, ProtocolError, UsageError
from tokenring.program import load_program
from tokenring.protocol import Field, Protocol, default_protocol, fields_struct
from tokenring.ring import EPOCH_MASK

if TYPE_CHECKING:
    from tokenring.node import NodeOS
    from tokenring.pclink import PcLinkServer

log = logging.getLogger("tokenring.system")

#: the 8051's code space: a node accepts programs up to this many bytes unless told otherwise
DEFAULT_CAPACITY = 65536
STORE_ENV = "TOKENRING_STORE"
NO_ACK_LIMIT = 10  # rounds a live target may leave a command unacknowledged
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


ENCODINGS = {0: "raw", 1: "zlib"}


def now_ms() -> int:
    return int(time.time() * 1000)


def file_stamp(path: Path) -> int:
    """A program file's time stamp (version): its modification time in ms."""
    return int(path.stat().st_mtime_ns // 1_000_000)


def format_stamp(stamp_ms: int) -> str:
    if not stamp_ms:
        return "-"
    return time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(stamp_ms / 1000)) + f".{stamp_ms % 1000:03d}"


def default_store_root() -> Path:
    """``$TOKENRING_STORE``, else ``$XDG_STATE_HOME/tokenring``, else ``~/.local/state/tokenring``."""
    env = os.environ.get(STORE_ENV)
    if env:
        return Path(env)
    state = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(state) / "tokenring"


def _text(raw: bytes) -> str:
    return raw.split(b"\0", 1)[0].decode("utf-8", "replace")


def _short(text: str, size: int) -> bytes:
    return text.encode("utf-8", "replace")[:size]


# ---------------------------------------------------------------------------------------------
# the per-node program store


@dataclass
class Installed:
    """A node's installed program: its source, digest, time stamp and (once compiled) class."""

    source: bytes
    digest: bytes
    stamp_ms: int
    filename: str
    program_class: type | None = None

    @property
    def size(self) -> int:
        return len(self.source)


class ProgramStore:
    """One node's battery-backed RAM: ``<dir>/program.json`` names ``<dir>/<sha12>/<module>.py``.

    A new program is written into its own version directory first; rewriting ``program.json``
    (atomically, ``os.replace``) is the commit, then older versions are removed. A store whose
    file does not match its recorded hash is reported and ignored (the node boots bare)."""

    META = "program.json"

    def __init__(self, directory: Path | None, module: str) -> None:
        self.directory = directory
        self.module = module

    def load(self) -> Installed | None:
        if self.directory is None:
            return None
        meta_path = self.directory / self.META
        try:
            meta = json.loads(meta_path.read_text(encoding="utf-8"))
            file = self.directory / meta["file"]
            source = file.read_bytes()
            digest = bytes.fromhex(meta["sha256"])
            stamp = int(meta["stamp_ms"])
        except FileNotFoundError:
            return None
        except (OSError, ValueError, KeyError, TypeError) as exc:
            log.warning("program store %s is unreadable (%s): booting bare", meta_path, exc)
            return None
        if hashlib.sha256(source).digest() != digest:
            log.warning("program store %s: %s does not match its hash: booting bare", meta_path, file)
            return None
        return Installed(source, digest, stamp, str(file))

    def save(self, source: bytes, digest: bytes, stamp_ms: int) -> str:
        """Install ``source``; returns the stored file's path. Raises OSError."""
        if self.directory is None:
            return f"<{self.module}>"
        version = self.directory / digest.hex()[:12]
        version.mkdir(parents=True, exist_ok=True)
        file = version / f"{self.module}.py"
        tmp = file.with_suffix(".py.tmp")
        tmp.write_bytes(source)
        os.replace(tmp, file)
        meta = {
            "module": self.module,
            "file": str(file.relative_to(self.directory)),
            "sha256": digest.hex(),
            "stamp_ms": stamp_ms,
            "size": len(source),
            "installed_at": time.strftime("%Y-%m-%dT%H:%M:%S"),
        }
        meta_tmp = self.directory / (self.META + ".tmp")
        meta_tmp.write_text(json.dumps(meta, indent=1) + "\n", encoding="utf-8")
        os.replace(meta_tmp, self.directory / self.META)
        for other in self.directory.iterdir():
            if other.is_dir() and other != version:
                shutil.rmtree(other, ignore_errors=True)
        return str(file)


# ---------------------------------------------------------------------------------------------
# issuer side: transactions


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
    done: threading.Event = field(default_factory=threading.Event)
    cancelled: bool = False
    started: float = 0.0
    finished: float = 0.0
    poll_deadline: float = 0.0
    epoch: int = -1

    @property
    def ok(self) -> bool:
        return self.done.is_set() and self.error is None

    def progress(self) -> dict[str, Any]:
        end = self.finished or time.monotonic()
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


class SystemLayer:
    """One node's system commands: the token handler hook, the issuer's transactions, the
    receiver's answers, a worker thread for slow effects and the program store."""

    def __init__(
        self,
        os_: NodeOS,
        *,
        store: ProgramStore | None = None,
        capacity: int = DEFAULT_CAPACITY,
        starter: Callable[[type], None] | None = None,
    ) -> None:
        self.os = os_
        self.me = os_.node_id
        self.store = store or ProgramStore(None, os_.name)
        self.capacity = capacity
        self.starter = starter or (lambda cls: os_.start_program(cls))
        self.stats = SystemStats()
        protocol = os_.protocol
        header = protocol.header
        self._o_issuer = header.syscmd_issuer
        self._o_target = header.syscmd_target
        self._o_code = header.syscmd_code
        self._o_length = header.syscmd_length
        self._o_ack = header.syscmd_ack
        self._o_epoch = header.epoch
        self._o_origin = header.epoch_origin
        self.all_nodes = protocol.all_nodes
        self.w0 = protocol.system_data_offset
        self.wsize = protocol.system_data_size
        self.w1 = self.w0 + self.wsize
        self.layouts = WindowLayouts.of(protocol)
        self.chunk_size = self.wsize - self.layouts.INDEX.size
        codes = protocol.system_commands
        self.codes = dict(codes)
        self.SCAN = codes["ARCNET_SCAN"]
        self.GET_CONFIG = codes["ARCNET_GET_CONFIG"]
        self.SEND_CONFIG = codes["ARCNET_SEND_CONFIG"]
        self.DATA = codes["ARCNET_DOWNLOAD_DATA"]
        self.TERMINATED = codes["ARCNET_DOWNLOAD_TERMINATED"]
        self.START_SYSTEM = codes["ARCNET_START_SYSTEM"]
        self.STOP_SYSTEM = codes["ARCNET_STOP_SYSTEM"]
        self.START_PROGRAM = codes["ARCNET_START_PROGRAM"]
        self.STOP_PROGRAM = codes["ARCNET_STOP_PROGRAM"]
        self.ERROR = codes["ARCNET_ERROR"]
        self.BEGIN = codes["ARCNET_DOWNLOAD_BEGIN"]
        self.GET_STATUS = codes["ARCNET_GET_STATUS"]
        self._receivers: dict[int, Callable[[bytearray], None]] = {
            self.SCAN: self._take_scan,
            self.GET_CONFIG: self._take_get_config,
            self.SEND_CONFIG: self._take_send_config,
            self.BEGIN: self._take_begin,
            self.DATA: self._take_data,
            self.TERMINATED: self._take_terminated,
            self.START_SYSTEM: self._take_start_system,
            self.STOP_SYSTEM: self._take_stop_system,
            self.START_PROGRAM: self._take_start_program,
            self.STOP_PROGRAM: self._take_stop_program,
            self.ERROR: self._take_error,
            self.GET_STATUS: self._take_get_status,
        }

        # issuer
        self._queue: deque[Transaction] = deque()
        self._current: Transaction | None = None
        self.os.system_busy = False  # a transaction is queued or in flight: the node skips us when idle
        self._lock = threading.Lock()  # _queue and system_busy change together
        self._saved: bytes | None = None
        self._rest = False  # leave the next free round to others

        # receiver
        self._download: _Download | None = None
        self._verified: Installed | None = None
        self._job: _Job | None = None
        self.installed: Installed | None = self.store.load()
        self._running_digest: bytes | None = None
        self._error_parts: dict[int, dict[int, bytes]] = {}
        self.errors: deque[dict[str, Any]] = deque(maxlen=200)
        self._error_count = itertools.count(1)
        self.corrupt_chunk: int | None = None  # test hook: damage this chunk index once stored
        self._reported_program: Any = None
        self._work: queue.SimpleQueue[tuple[Callable[..., None], tuple[Any, ...]] | None] = (
            queue.SimpleQueue()
        )
        self._worker: threading.Thread | None = None
        self._closing = False

    # =========================================================================================
    # life cycle

    def install(self) -> SystemLayer:
        """Hook into the node OS and start the worker thread."""
        self.os.system_handler = self.handle
        self.os.on_program_error = lambda: self._work.put((self._watch_program, ()))
        self._worker = threading.Thread(target=self._work_loop, name=f"system-{self.me}", daemon=True)
        self._worker.start()
        return self

    def close(self) -> None:
        self._closing = True
        self._work.put(None)
        if self._worker is not None and self._worker is not threading.current_thread():
            self._worker.join(1.0)

    # =========================================================================================
    # the token handler hook (hot path)

    def handle(self, work: bytearray) -> bool:
        """Called at every token visit; True while a system command is active (user channels pause)."""
        issuer = work[self._o_issuer]
        if not issuer:
            if not self.os.system_busy:
                return False
            return self._begin(work)
        if issuer == self.me:
            return self._returned(work)
        if issuer not in self.os.membership.active:
            self._clear_orphan(work, issuer)
            return self._begin(work) if self.os.system_busy else False
        target = work[self._o_target]
        if target == self.me or target == self.all_nodes:
            self._take(work)
        return True

    def _take(self, work: bytearray) -> None:
        receiver = self._receivers.get(work[self._o_code])
        self.stats.commands_taken += 1
        if receiver is None:
            work[self.w0] = Status.UNKNOWN_COMMAND
        else:
            receiver(work)
        if work[self._o_target] != self.all_nodes or not work[self._o_ack]:
            work[self._o_ack] = self.me

    def _clear_orphan(self, work: bytearray, issuer: int) -> None:
        """The issuer left or hangs: nobody will restore its window; clear it (zeros are every
        channel's initial state) so that user communication resumes."""
        self.stats.orphans_cleared += 1
        log.warning("system command of node %d cleared: the node is no longer on the ring", issuer)
        for offset in (self._o_issuer, self._o_target, self._o_code, self._o_length, self._o_ack):
            work[offset] = 0
        work[self.w0 : self.w1] = bytes(self.wsize)

    def _epoch(self, work: bytearray) -> int:
        return ((work[self._o_epoch] & EPOCH_MASK) << 8) | work[self._o_origin]

    def _begin(self, work: bytearray) -> bool:
        """The token is free of system commands and we have one to send."""
        tx = self._current
        if tx is not None:
            # our command vanished from the token (regenerated from an older copy, cleared as an
            # orphan while we hung): the window was not restored by us, so save it again
            tx.lost += 1
            self.stats.lost_commands += 1
            if tx.lost > LOST_LIMIT:
                self._finish(tx, f"the command vanished from the token {tx.lost} times")
                return False
        else:
            if self._rest:
                self._rest = False
                return False
            with self._lock:
                if not self._queue:
                    self.os.system_busy = False
                    return False
                tx = self._queue.popleft()
            self._current = tx
            tx.started = time.monotonic()
        self._saved = bytes(work[self.w0 : self.w1])
        self._write(work, tx)
        return True

    def _write(self, work: bytearray, tx: Transaction) -> None:
        step = tx.steps[tx.index]
        payload = step.payload
        work[self._o_issuer] = self.me
        work[self._o_target] = step.target
        work[self._o_code] = step.code
        work[self._o_length] = len(payload)
        work[self._o_ack] = 0
        work[self.w0 : self.w0 + len(payload)] = payload
        tx.epoch = self._epoch(work)
        self.stats.commands_issued += 1
        if step.target == self.me or step.target == self.all_nodes:
            self._take(work)  # the issuer is its own first receiver

    def _returned(self, work: bytearray) -> bool:
        """Our command made the round: read the answer, then the next step, or restore."""
        tx = self._current
        if tx is None:  # an old copy of a finished command came back after a regeneration
            self._restore(work)
            return False
        tx.rounds += 1
        if tx.cancelled:
            self._finish(tx, "cancelled (timed out)")
            return self._next_or_restore(work)
        if self._epoch(work) != tx.epoch:  # the answer may belong to an older copy: resend
            tx.resends += 1
            self.stats.resends += 1
            self._write(work, tx)
            return True
        step = tx.steps[tx.index]
        if step.target != self.all_nodes:
            if work[self._o_ack] != step.target:
                tx.retries += 1
                if step.target not in self.os.membership.live:
                    self._finish(tx, f"node {step.target} left the ring")
                    return self._next_or_restore(work)
                if tx.retries > NO_ACK_LIMIT:
                    self._finish(tx, f"node {step.target} did not acknowledge")
                    return self._next_or_restore(work)
                tx.resends += 1
                self.stats.resends += 1
                self._write(work, tx)
                return True
            status = work[self.w0]
            if status == Status.PENDING and step.poll:
                now = time.monotonic()
                if not tx.poll_deadline:
                    tx.poll_deadline = now + POLL_TIMEOUT_S
                elif now > tx.poll_deadline:
                    self._finish(tx, f"node {step.target} did not finish within {POLL_TIMEOUT_S:.0f} s")
                    return self._next_or_restore(work)
                self._write(work, tx)
                return True
            if status != Status.OK:
                tx.status = Status(status) if status in Status._value2member_map_ else None
                detail = _text(bytes(work[self.w0 + 1 : self.w1]))
                name = tx.status.name if tx.status is not None else f"status {status}"
                self._finish(tx, f"{name}: {detail}" if detail else name)
                return self._next_or_restore(work)
        if step.keep:
            tx.answers[tx.index] = bytes(work[self.w0 : self.w1])
        tx.index += 1
        tx.retries = 0
        tx.poll_deadline = 0.0
        if tx.index < len(tx.steps):
            self._write(work, tx)
            return True
        self._finish(tx, None)
        return self._next_or_restore(work)

    def _finish(self, tx: Transaction, error: str | None) -> None:
        if error is not None:
            tx.error = error
            tx.failed_step = tx.index
        tx.finished = time.monotonic()
        if self._current is tx:
            self._current = None
        tx.done.set()

    def _next_or_restore(self, work: bytearray) -> bool:
        self._restore(work)
        self._rest = True  # one free round for others before our next transaction
        with self._lock:
            self.os.system_busy = bool(self._queue) or self._current is not None
        return False

    def _restore(self, work: bytearray) -> None:
        for offset in (self._o_issuer, self._o_target, self._o_code, self._o_length, self._o_ack):
            work[offset] = 0
        if self._saved is not None:
            work[self.w0 : self.w1] = self._saved

    # =========================================================================================
    # issuer API (any thread)

    def submit(self, steps: list[Step], what: str = "") -> Transaction:
        tx = Transaction(steps, what)
        if not steps:
            tx.done.set()
            return tx
        with self._lock:
            self._queue.append(tx)
            self.os.system_busy = True
        return tx

    def execute(self, steps: list[Step], what: str = "", timeout: float = 10.0) -> Transaction:
        """Submit and wait; raises :class:`SystemCommandError` if it failed or timed out."""
        tx = self.submit(steps, what)
        if not tx.done.wait(timeout):
            tx.cancelled = True
            with self._lock, contextlib.suppress(ValueError):
                self._queue.remove(tx)
            raise SystemCommandError(f"{what or 'system command'}: no answer within {timeout:.0f} s")
        if tx.error is not None:
            step = tx.steps[tx.failed_step or 0]
            raise SystemCommandError(f"{what}: {tx.error}", tx.status, step.target)
        return tx

    def scan(self, timeout: float = 5.0) -> list[int]:
        """ARCNET_SCAN: the IDs of every node that answered in one round."""
        bitmap = bytearray(self.wsize)
        tx = self.execute([Step(self.all_nodes, self.SCAN, bytes(bitmap), keep=True)], "scan", timeout)
        answer = tx.answers[0]
        return [i for i in range(1, 256) if i >> 3 < len(answer) and answer[i >> 3] & (1 << (i & 7))]

    def configs(self, ids: list[int], timeout: float = 10.0) -> dict[int, dict[str, Any]]:
        """ARCNET_GET_CONFIG of each node (one transaction, one round each)."""
        steps = [Step(i, self.GET_CONFIG, keep=True) for i in ids]
        tx = self.execute(steps, "get config", timeout)
        return {ids[i]: decode_config(answer, ids[i], self.layouts) for i, answer in tx.answers.items()}

    def download_steps(
        self, target: int, source: bytes, stamp_ms: int, *, compress: bool = True, start: bool = False
    ) -> list[Step]:
        """BEGIN, one DATA per chunk, TERMINATED (verify), SEND_CONFIG (install), START_PROGRAM."""
        blob = zlib.compress(source, 9) if compress else source
        encoding = 1 if compress else 0
        if compress and len(blob) >= len(source):
            blob, encoding = source, 0
        size = self.chunk_size
        chunks = (len(blob) + size - 1) // size
        if chunks > 0xFFFF:
            raise UsageError(f"a program of {len(source)} bytes needs {chunks} chunks, more than 65535")
        digest = hashlib.sha256(source).digest()
        steps = [Step(target, self.BEGIN, self.layouts.BEGIN.pack(len(source), len(blob), encoding, size))]
        steps += [
            Step(target, self.DATA, self.layouts.INDEX.pack(i) + blob[i * size : (i + 1) * size])
            for i in range(chunks)
        ]
        steps.append(Step(target, self.TERMINATED, digest, poll=True))
        steps.append(Step(target, self.SEND_CONFIG, self.layouts.STAMP.pack(stamp_ms, digest[:8]), poll=True))
        if start:
            steps.append(self.start_step(target))
        return steps

    def start_step(self, target: int) -> Step:
        return Step(target, self.START_PROGRAM, self.layouts.NONCE.pack(random.getrandbits(32)), poll=True)

    def stop_step(self, target: int) -> Step:
        return Step(target, self.STOP_PROGRAM, self.layouts.NONCE.pack(random.getrandbits(32)), poll=True)

    def restamp_step(self, target: int, digest: bytes, stamp_ms: int) -> Step:
        return Step(target, self.SEND_CONFIG, self.layouts.STAMP.pack(stamp_ms, digest[:8]), poll=True)

    def broadcast(self, code: int, what: str, timeout: float = 5.0) -> list[int]:
        """START_SYSTEM / STOP_SYSTEM: the IDs of the nodes that took it."""
        tx = self.execute([Step(self.all_nodes, code, bytes(self.wsize), keep=True)], what, timeout)
        answer = tx.answers[0]
        return [i for i in range(1, 256) if answer[i >> 3] & (1 << (i & 7))]

    def status_of(self, target: int, timeout: float = 5.0) -> dict[str, Any]:
        tx = self.execute([Step(target, self.GET_STATUS, keep=True)], "get status", timeout)
        _, state, current, error = self.layouts.STATUS.unpack(tx.answers[0])
        return {"state": State(state).name, "runs_installed": bool(current), "error": _text(error) or None}

    # =========================================================================================
    # receiver side (in the token handler: byte copies only)

    def _set_bit(self, work: bytearray) -> None:
        work[self.w0 + (self.me >> 3)] |= 1 << (self.me & 7)

    def _bit_set(self, work: bytearray) -> bool:
        return bool(work[self.w0 + (self.me >> 3)] & (1 << (self.me & 7)))

    def _answer(self, work: bytearray, status: Status, detail: str = "") -> None:
        work[self.w0] = status
        if detail or status != Status.OK:
            raw = _short(detail, self.wsize - 1)
            work[self.w0 + 1 : self.w1] = raw + bytes(self.wsize - 1 - len(raw))

    def _take_scan(self, work: bytearray) -> None:
        self._set_bit(work)

    def _take_get_config(self, work: bytearray) -> None:
        installed = self.installed
        if installed is None:
            stamp, size, digest = 0, 0, bytes(8)
        else:
            stamp, size, digest = installed.stamp_ms, installed.size, installed.digest[:8]
        work[self.w0 : self.w1] = self.layouts.CONFIG.pack(
            Status.OK, self.program_state(), stamp, size, digest, _short(self.os.name, 10)
        )

    def _take_get_status(self, work: bytearray) -> None:
        error = self.os.program_error or ""
        work[self.w0 : self.w1] = self.layouts.STATUS.pack(
            Status.OK, self.program_state(), self._runs_installed(), _short(error, 29)
        )

    def _take_begin(self, work: bytearray) -> None:
        size, transfer, encoding, chunk = self.layouts.BEGIN.unpack_from(work, self.w0)
        self._job = None
        self._download = None
        if size > self.capacity:
            self._answer(work, Status.REFUSED, f"accepts up to {self.capacity} bytes")
            return
        if encoding not in ENCODINGS or not 0 < chunk <= self.chunk_size or transfer > 2 * self.capacity + 64:
            self._answer(work, Status.REFUSED, "bad download header")
            return
        chunks = (transfer + chunk - 1) // chunk
        self._download = _Download(size, transfer, encoding, chunk, chunks, bytearray(transfer))
        self.stats.downloads_begun += 1
        self._answer(work, Status.OK)

    def _take_data(self, work: bytearray) -> None:
        dl = self._download
        index = work[self.w0] | (work[self.w0 + 1] << 8)
        if dl is None:
            self._answer(work, Status.NOT_DOWNLOADING, "no DOWNLOAD_BEGIN")
            return
        if index == dl.next:
            n = work[self._o_length] - 2
            start = index * dl.chunk
            if n < 0 or start + n > dl.transfer:
                self._answer(work, Status.BAD_SEQUENCE, f"chunk {index} overruns the program")
                return
            dl.buffer[start : start + n] = work[self.w0 + 2 : self.w0 + 2 + n]
            if index == self.corrupt_chunk and n:  # test hook: a bad write into the node's RAM
                dl.buffer[start] ^= 0x20
                self.corrupt_chunk = None
            dl.next = index + 1
            self.stats.chunks_received += 1
            self.stats.bytes_received += n
            work[self.w0] = Status.OK
        elif index + 1 == dl.next:
            self.stats.chunk_repeats += 1
            work[self.w0] = Status.OK
        else:
            self._answer(work, Status.BAD_SEQUENCE, f"chunk {index}, expected {dl.next}")

    def _job_answer(self, work: bytearray, key: bytes) -> bool:
        """A repeat of the command whose job runs (or ran): answer its status."""
        job = self._job
        if job is None or job.key != key:
            return False
        self._answer(work, job.status, job.detail)
        return True

    def _new_job(self, work: bytearray, key: bytes, action: Callable[..., None], *args: Any) -> None:
        job = _Job(key)
        self._job = job
        self._work.put((action, (job, *args)))
        work[self.w0] = Status.PENDING

    def _take_terminated(self, work: bytearray) -> None:
        key = bytes([self.TERMINATED]) + bytes(work[self.w0 : self.w1])
        if self._job_answer(work, key):
            return
        dl = self._download
        if dl is None:
            self._answer(work, Status.NOT_DOWNLOADING, "no download in progress")
            return
        if dl.next < dl.chunks:
            self._answer(work, Status.BAD_SEQUENCE, f"incomplete: {dl.next} of {dl.chunks} chunks")
            return
        self._download = None
        self._new_job(work, key, self._verify, dl, bytes(work[self.w0 : self.w1]))

    def _take_send_config(self, work: bytearray) -> None:
        key = bytes([self.SEND_CONFIG]) + bytes(work[self.w0 : self.w0 + self.layouts.STAMP.size])
        if self._job_answer(work, key):
            return
        stamp, digest8 = self.layouts.STAMP.unpack_from(work, self.w0)
        verified, installed = self._verified, self.installed
        if verified is not None and verified.digest[:8] == digest8:
            self._new_job(work, key, self._install, verified, stamp)
        elif installed is not None and installed.digest[:8] == digest8:
            self._new_job(work, key, self._install, installed, stamp)
        else:
            self._answer(work, Status.NO_PROGRAM, "no verified download with this hash")

    def _take_start_program(self, work: bytearray) -> None:
        key = bytes([self.START_PROGRAM]) + bytes(work[self.w0 : self.w0 + self.layouts.NONCE.size])
        if not self._job_answer(work, key):
            self._new_job(work, key, self._start)

    def _take_stop_program(self, work: bytearray) -> None:
        key = bytes([self.STOP_PROGRAM]) + bytes(work[self.w0 : self.w0 + self.layouts.NONCE.size])
        if not self._job_answer(work, key):
            self._new_job(work, key, self._stop)

    def _take_start_system(self, work: bytearray) -> None:
        if self.installed is not None and not self._bit_set(work):
            self._set_bit(work)
            self._work.put((self._start, (None,)))

    def _take_stop_system(self, work: bytearray) -> None:
        if not self._bit_set(work):
            self._set_bit(work)
            self._work.put((self._stop, (None,)))

    def _take_error(self, work: bytearray) -> None:
        part, about, text = self.layouts.ERROR.unpack_from(work, self.w0)
        issuer = work[self._o_issuer]
        parts = self._error_parts.setdefault(issuer, {})
        parts[part & 0x7F] = text.rstrip(b"\0")
        work[self.w0] = Status.OK
        if part & 0x80:
            raw = b"".join(parts[i] for i in sorted(parts))
            del self._error_parts[issuer]
            self._work.put((self._record_error, (issuer, about, raw.decode("utf-8", "replace"))))

    # =========================================================================================
    # the worker: slow effects, off the token path

    def _work_loop(self) -> None:
        while not self._closing:
            # blocks: a failed program wakes it through NodeOS.on_program_error (no polling,
            # which 255 idle nodes would pay for 5 times a second each)
            item = self._work.get()
            if item is None:
                return
            action, args = item
            try:
                action(*args)
            except Exception as exc:  # the worker must survive anything
                log.exception("system worker: %s", exc)
                if args and isinstance(args[0], _Job):
                    args[0].detail = f"{type(exc).__name__}: {exc}"
                    args[0].status = Status.STORE_ERROR
            self._watch_program()

    def _verify(self, job: _Job, dl: _Download, digest: bytes) -> None:
        data = bytes(dl.buffer)
        if dl.encoding == 1:
            try:
                inflater = zlib.decompressobj()
                data = inflater.decompress(data, dl.size + 1)
            except zlib.error as exc:
                self._reject(job, Status.CORRUPT, f"cannot inflate: {exc}")
                return
        if len(data) != dl.size:
            self._reject(job, Status.CORRUPT, f"{len(data)} bytes, not {dl.size}")
            return
        got = hashlib.sha256(data).digest()
        if got != digest:
            self._reject(job, Status.CORRUPT, f"hash {got.hex()[:8]}, sent {digest.hex()[:8]}")
            return
        filename = f"{self.os.name}.py"
        try:
            program_class = load_program(data, filename)
        except ProgramError as exc:  # the status has room for 31 bytes, ARCNET_ERROR for all
            self._reject(job, Status.LOAD_ERROR, str(exc).removeprefix(filename).lstrip(": "))
            self._send_error(self.TERMINATED, str(exc))
            return
        wanted = getattr(program_class, "module", "")
        if wanted and wanted != self.os.name:
            self._reject(job, Status.LOAD_ERROR, f"program of {wanted!r}")
            return
        self._verified = Installed(data, digest, 0, filename, program_class)
        self.stats.downloads_verified += 1
        job.status = Status.OK

    def _reject(self, job: _Job, status: Status, detail: str) -> None:
        self.stats.downloads_rejected += 1
        log.warning("download rejected: %s: %s (the previous program stays)", status.name, detail)
        job.detail = detail
        job.status = status

    def _install(self, job: _Job, program: Installed, stamp_ms: int) -> None:
        try:
            filename = self.store.save(program.source, program.digest, stamp_ms)
        except OSError as exc:
            job.detail = f"store: {exc.strerror or exc}"
            job.status = Status.STORE_ERROR
            return
        self.installed = Installed(program.source, program.digest, stamp_ms, filename, program.program_class)
        if self._verified is program:
            self._verified = None
        self.stats.installs += 1
        log.info(
            "program installed: %d bytes, sha256 %s, time stamp %s",
            program.size,
            program.digest.hex()[:12],
            format_stamp(stamp_ms),
        )
        job.status = Status.OK

    def _start(self, job: _Job | None) -> None:
        installed = self.installed
        if installed is None:
            if job is not None:
                job.detail, job.status = "no program installed", Status.NO_PROGRAM
            return
        if self.program_state() == State.RUNNING and self._running_digest == installed.digest:
            if job is not None:
                job.status = Status.OK
            return
        try:
            if installed.program_class is None:
                installed.program_class = load_program(installed.source, installed.filename)
            self.starter(installed.program_class)
        except Exception as exc:
            line = str(exc) if isinstance(exc, ProgramError) else f"{type(exc).__name__}: {exc}"
            self._send_error(self.START_PROGRAM, line)
            if job is not None:
                job.detail, job.status = line, Status.START_FAILED
            return
        self._running_digest = installed.digest
        self.stats.starts += 1
        program = self.os.program
        deadline = time.monotonic() + START_GRACE_S
        while time.monotonic() < deadline and self.os.program_error is None:
            time.sleep(0.02)
        if self.os.program_error is not None and self.os.program is program:
            self._report_program_error(program)
            if job is not None:
                job.detail, job.status = self.os.program_error, Status.START_FAILED
            return
        if job is not None:
            job.status = Status.OK

    def _stop(self, job: _Job | None) -> None:
        if self.os.program is not None:
            self.os.stop_program()
            self.stats.stops += 1
        self._running_digest = None
        if job is not None:
            job.status = Status.OK

    def _watch_program(self) -> None:
        """Report a program that raised (on start or later) through ARCNET_ERROR, once."""
        program = self.os.program
        if (
            program is not None
            and self.os.program_error is not None
            and self._reported_program is not program
        ):
            self._report_program_error(program)

    def _report_program_error(self, program: Any) -> None:
        if self._reported_program is program:
            return
        self._reported_program = program
        self._send_error(0, self.os.program_error or "failed")

    def _send_error(self, about: int, text: str) -> None:
        """ARCNET_ERROR to the master: ``text`` in 30-byte parts (up to 240 bytes)."""
        raw = text.encode("utf-8", "replace")[: 30 * ERROR_PARTS] or b"?"
        parts = [raw[i : i + 30] for i in range(0, len(raw), 30)]
        master = self.os.preferred_master or self.me
        steps = [
            Step(
                master,
                self.ERROR,
                self.layouts.ERROR.pack(i | (0x80 if i == len(parts) - 1 else 0), about, part),
            )
            for i, part in enumerate(parts)
        ]
        self.stats.errors_sent += 1
        self.submit(steps, "error report")

    def _record_error(self, issuer: int, about: int, text: str) -> None:
        spec = self.os.protocol.by_id.get(issuer)
        entry = {
            "n": next(self._error_count),
            "node": issuer,
            "name": spec.name if spec else f"node{issuer}",
            "about": self.os.protocol.system_command_name(about) if about else "program",
            "text": text,
            "time_ms": now_ms(),
        }
        self.stats.errors_received += 1
        self.errors.append(entry)
        log.warning("ARCNET_ERROR from %s (id %d, %s): %s", entry["name"], issuer, entry["about"], text)

    # =========================================================================================
    # state

    def program_state(self) -> State:
        os_ = self.os
        program = os_.program
        if program is None:
            return State.STOPPED if self.installed is not None else State.NONE
        if os_.program_error is not None:
            return State.FAILED
        thread = os_._program_thread
        return State.RUNNING if thread is not None and thread.is_alive() else State.STOPPED

    def _runs_installed(self) -> bool:
        installed = self.installed
        return bool(
            installed is not None
            and self._running_digest == installed.digest
            and self.program_state() == State.RUNNING
        )

    def adopt(self, source: bytes, stamp_ms: int, filename: str, program_class: type) -> None:
        """A program started from a file (``--program``): report it as installed (not stored)."""
        digest = hashlib.sha256(source).digest()
        self.installed = Installed(source, digest, stamp_ms, filename, program_class)
        self._running_digest = digest

    def start_installed(self) -> bool:
        """Start the stored program at boot (``--autostart``); False if there is none."""
        if self.installed is None:
            return False
        self._work.put((self._start, (None,)))
        return True

    def report(self) -> dict[str, Any]:
        """The control verb ``system``: counters, the installed program, the error log."""
        installed = self.installed
        return {
            "stats": vars(self.stats).copy(),
            "state": self.program_state().name,
            "runs_installed": self._runs_installed(),
            "installed": None
            if installed is None
            else {
                "size": installed.size,
                "sha256": installed.digest.hex(),
                "stamp_ms": installed.stamp_ms,
                "file": installed.filename,
            },
            "store": str(self.store.directory) if self.store.directory else None,
            "capacity": self.capacity,
            "errors": list(self.errors),
        }

    def control(self, request: dict[str, Any]) -> dict[str, Any]:
        """Control verb ``system``: the report; ``{"corrupt_chunk": N}`` arms the test hook."""
        if "corrupt_chunk" in request:
            value = request["corrupt_chunk"]
            if not isinstance(value, int) or value < 0:
                raise UsageError("corrupt_chunk needs a chunk index >= 0")
            self.corrupt_chunk = value
        return self.report()


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


class PcSystemVerbs:
    """The system commands on main's serial line: ``scan``, ``download``, ``job``, ``start``,
    ``stop``, ``errors`` (see :mod:`tokenring.pclink`). Downloads run as jobs the PC polls, so
    the serial line stays free for progress requests."""

    def __init__(self, layer: SystemLayer) -> None:
        self.layer = layer
        self.jobs: dict[int, Transaction] = {}
        self._ids = itertools.count(1)

    def register(self, server: PcLinkServer) -> None:
        for verb in ("scan", "download", "job", "start", "stop", "errors"):
            server.register(verb, getattr(self, verb))

    def _node(self, value: Any) -> int:
        if isinstance(value, int) and 1 <= value <= 255:
            return value
        try:
            return self.layer.os.protocol.node(str(value)).id
        except Exception as exc:
            raise UsageError(str(exc)) from None

    def _live(self, node_id: int) -> None:
        if node_id not in self.layer.os.membership.live:
            raise UsageError(f"node {node_id} is not on the ring")

    def scan(self, request: dict[str, Any]) -> dict[str, Any]:
        """ARCNET_SCAN, then ARCNET_GET_CONFIG of every node found."""
        layer = self.layer
        t0 = time.monotonic()
        ids = layer.scan(float(request.get("timeout", 5.0)))
        configs = layer.configs(ids) if ids else {}
        return {"nodes": [configs[i] for i in ids if i in configs], "seconds": time.monotonic() - t0}

    def download(self, request: dict[str, Any]) -> dict[str, Any]:
        """``{target, source, stamp_ms, compress, start}`` → ``{job, chunks, bytes}``."""
        target = self._node(request.get("target"))
        self._live(target)
        source = request.get("source")
        if not isinstance(source, bytes):
            raise UsageError("download needs the program's source as bytes")
        stamp = int(request.get("stamp_ms") or now_ms())
        if request.get("restamp"):  # the node has this very program: only the new time stamp
            steps = [self.layer.restamp_step(target, hashlib.sha256(source).digest(), stamp)]
        else:
            steps = self.layer.download_steps(
                target,
                source,
                stamp,
                compress=bool(request.get("compress", True)),
                start=bool(request.get("start", False)),
            )
        tx = self.layer.submit(steps, f"download to {target}")
        job = next(self._ids)
        self.jobs[job] = tx
        for old in [j for j in self.jobs if j < job - 50]:
            del self.jobs[old]
        chunks = sum(1 for s in steps if s.code == self.layer.DATA)
        return {
            "job": job,
            "chunks": chunks,
            "bytes": sum(len(s.payload) - 2 for s in steps if s.code == self.layer.DATA),
        }

    def job(self, request: dict[str, Any]) -> dict[str, Any]:
        tx = self.jobs.get(int(request.get("job", 0)))
        if tx is None:
            raise UsageError(f"no download job {request.get('job')!r}")
        if request.get("cancel") and not tx.done.is_set():
            tx.cancelled = True
        progress = tx.progress()
        if tx.failed_step is not None and tx.failed_step < len(tx.steps):
            code = tx.steps[tx.failed_step].code
            progress["failed_command"] = self.layer.os.protocol.system_command_name(code)
        return progress

    def start(self, request: dict[str, Any]) -> dict[str, Any]:
        """The whole system (ARCNET_START_SYSTEM) or one node's program (ARCNET_START_PROGRAM)."""
        return self._start_stop(request, start=True)

    def stop(self, request: dict[str, Any]) -> dict[str, Any]:
        return self._start_stop(request, start=False)

    def _start_stop(self, request: dict[str, Any], start: bool) -> dict[str, Any]:
        layer = self.layer
        timeout = float(request.get("timeout", 10.0))
        target = request.get("target")
        if target in (None, "", "all"):
            code, what = (layer.START_SYSTEM, "start system") if start else (layer.STOP_SYSTEM, "stop system")
            return {"nodes": layer.broadcast(code, what, timeout)}
        node = self._node(target)
        self._live(node)
        step = layer.start_step(node) if start else layer.stop_step(node)
        try:
            layer.execute([step], ("start" if start else "stop") + f" program of {node}", timeout)
        except SystemCommandError as exc:
            return {"nodes": [], "error": str(exc)}
        return {"nodes": [node]}

    def errors(self, request: dict[str, Any]) -> dict[str, Any]:
        since = int(request.get("since", 0))
        return {"errors": [e for e in self.layer.errors if e["n"] > since]}
