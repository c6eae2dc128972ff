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

import itertools
import logging
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from tokenring.node.node_os import NodeOS

from tokenring import runtime
from tokenring.node.store import Installed, ProgramStore
from tokenring.node.system.issuer import SystemIssuer
from tokenring.node.system.receiver import SystemReceiver
from tokenring.node.system.vocabulary import (
    DEFAULT_CAPACITY,
    SystemStats,
    Transaction,
    WindowLayouts,
    _Download,
    _Job,
)

log = logging.getLogger("tokenring.system")


class SystemLayer(SystemIssuer, SystemReceiver):
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
        self._rt = rt = runtime.current()  # its locks, queue, worker and clock (the node's)
        self._clock = rt.monotonic  # the issuer's transaction times
        self._rng = rt.rng()  # the start and stop commands' nonces
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
        self._lock = rt.lock()  # _queue and system_busy change together
        self._saved: bytes | None = None
        self._rest = False  # leave the next free round to others

        # receiver
        self._download: _Download | None = None
        self._verified: Installed | None = None
        self._job: _Job | None = None
        self.installed: Installed | None = self.store.load()
        self._previous: Installed | None = None
        self._running_digest: bytes | None = None
        self._error_parts: dict[int, dict[int, bytes]] = {}
        self.errors: deque[dict[str, Any]] = deque(maxlen=200)
        self._error_count = itertools.count(1)
        self.corrupt_chunk: int | None = None  # test hook: damage this chunk index once stored
        self._reported_program: Any = None
        self._work = rt.simple_queue()
        self._worker = None
        self._closing = False

    # =========================================================================================
    # life cycle

    def install(self) -> SystemLayer:
        """Hook into the node OS and start the worker thread."""
        self.os.system_handler = self.handle
        self.os.on_program_error = lambda: self._work.put((self._watch_program, ()))
        self._worker = self._rt.spawn(self._work_loop, f"system-{self.me}")
        return self

    def close(self) -> None:
        self._closing = True
        self._work.put(None)
        if self._worker is not None and self._worker is not self._rt.current_thread():
            self._worker.join(1.0)
