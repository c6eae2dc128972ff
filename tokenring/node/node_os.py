"""The node operating system: one token handler per visit, the ring's bookkeeping, the user API.

The handler (``_on_frame``) runs once per token visit, on the transport's receiving thread (or on
the node's token thread while a visit may wait: emulated wire time, a pacer, a fault hook):

1. check the frame (length, CRC-16/ARC, markers, DID, SID a ring member, pass not a repeat,
   epoch not stale) — anything else is dropped and counted, never raised;
2. system commands (a hook filled by :mod:`tokenring.node.system.layer`); while one is active the user
   channels pause everywhere;
3. the registered, unlocked user channels (data copies, inbox, outgoing commands);
4. where the ring wraps (main) the counter is incremented; the token goes to the successor at once.

Everything slower — timeouts, retries, regeneration, statistics — happens on a watchdog thread
off that path. User programs run in their own thread and talk to the handler only through
:class:`~tokenring.node.channels.ChannelBuffer` objects and a few flags.

Every clock read, wait, lock and thread comes from the runtime in force when the node is made
(:mod:`tokenring.runtime`): the operating system's, or a simulation's virtual clock and tasks,
in which the token path is the Python one (:meth:`NodeOS.__new__`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from tokenring import runtime
from tokenring.contract import ring as R
from tokenring.contract.protocol import Protocol
from tokenring.contract.ring import EPOCH_MASK
from tokenring.errors import TokenRingError
from tokenring.node.api import ProgramAPI
from tokenring.node.channels import CommandMemory, DataRegistration, Inbox, Outbox, _Offsets
from tokenring.node.program_host import ProgramHost
from tokenring.node.recovery import RingRecovery
from tokenring.node.tokenpath import HOT_COUNTERS, NATIVE, PyTokenPath, TokenPathBase, new_counters
from tokenring.transport.base import Transport

log = logging.getLogger("tokenring.node")


def _hot_counter(name: str) -> Any:
    """A counter the token path adds to on every visit: kept in its C integers (``counters``)."""

    def read(stats: NodeStats) -> int:
        count: int = getattr(stats.counters, name)
        return count

    def write(stats: NodeStats, value: int) -> None:
        setattr(stats.counters, name, value)

    return property(read, write, doc=f"{name} (the token path's own counter)")


class NodeStats:
    """Per-node counters, in the spirit of the Linux arcnet driver's."""

    FIELDS = (
        "frames_received",
        "frames_sent",
        "rejected_length",
        "rejected_crc",
        "rejected_marker",
        "rejected_did",
        "rejected_sid",
        "duplicate_passes",
        "stale_tokens",
        "replayed_passes",  # an older round of the current epoch delivered again: dropped
        "rounds",
        "rounds_missed",
        "visits",
        "passes_acked",
        "pass_retries",
        "unacked_passes",
        "successors_declared_dead",
        "successors_only_slow",  # declared dead but alive again at once: their ack timeout grew
        "successor_changes",
        "reconfigurations",
        "tokens_regenerated",
        "epoch_changes",
        "commands_sent",
        "commands_acknowledged",
        "commands_unacknowledged",
        "commands_received",
        "duplicate_commands",
        "stale_commands_cleared",
        "inbox_full",
        "send_errors",
        "system_commands",
        "watchdog_wakes",  # its timer thread's loops: each costs a sleeping process CPU
    )
    __slots__ = (*(name for name in FIELDS if name not in HOT_COUNTERS), "counters")
    frames_received = _hot_counter("frames_received")
    frames_sent = _hot_counter("frames_sent")
    rejected_length: int
    rejected_crc: int
    rejected_marker: int
    rejected_did: int
    rejected_sid: int
    duplicate_passes: int
    stale_tokens: int
    replayed_passes: int
    rounds = _hot_counter("rounds")
    rounds_missed = _hot_counter("rounds_missed")
    visits = _hot_counter("visits")
    passes_acked: int
    pass_retries: int
    unacked_passes: int
    successors_declared_dead: int
    successors_only_slow: int
    successor_changes: int
    reconfigurations: int
    tokens_regenerated: int
    epoch_changes: int
    commands_sent: int
    commands_acknowledged: int
    commands_unacknowledged: int
    commands_received: int
    duplicate_commands: int
    stale_commands_cleared: int
    inbox_full: int
    send_errors: int
    system_commands: int
    watchdog_wakes: int

    def __init__(self) -> None:
        self.counters = new_counters()
        for name in self.FIELDS:
            setattr(self, name, 0)

    def as_dict(self) -> dict[str, int]:
        return {name: getattr(self, name) for name in self.FIELDS}


class NodeOS(TokenPathBase, RingRecovery, ProgramAPI, ProgramHost):
    """One node of the ring: the token handler, ring membership and the user-program API."""

    def __new__(cls, *args: Any, **kwargs: Any) -> NodeOS:
        """A node; in a simulation one whose token path is the Python one, whatever was built:
        the C path reads the OS's clock and sleeps on it, which a virtual clock cannot see."""
        if cls is NodeOS and NATIVE and runtime.current().simulated:
            cls = _PythonPathNodeOS
        node: NodeOS = super().__new__(cls)
        return node

    def __init__(
        self,
        protocol: Protocol,
        node_id: int,
        transport: Transport,
        *,
        name: str | None = None,
        bitrate: float | None = None,
        ack_mode: str = "adaptive",
        master_id: int | None = None,
        expected_nodes: int | None = None,
    ) -> None:
        if not 1 <= node_id <= 255:
            raise TokenRingError(f"node ID {node_id} is outside 1..255")
        if ack_mode not in ("adaptive", "always", "never"):
            raise TokenRingError(f"ack mode must be adaptive, always or never, not {ack_mode!r}")
        #: the runtime this node waits on; its clock bound once, for the paths that read it often
        self._rt = rt = runtime.current()
        self._now = rt.monotonic
        self._sleep = rt.sleep
        self.protocol = protocol
        self.node_id = node_id
        self.transport = transport
        spec = protocol.by_id.get(node_id)
        self.spec = spec
        self.name = name or (spec.name if spec else f"node{node_id}")
        self.stats = NodeStats()
        self._counters = self.stats.counters
        self.timing = R.Timing(bitrate, ack_mode)
        self.membership = R.Membership(node_id, clock=rt.monotonic)
        if master_id is None and "main" in protocol.nodes:
            master_id = protocol.nodes["main"].id
        self.preferred_master = master_id  # starts the token at boot (the seed: main)

        header = protocol.header
        self._o_sid = header.sid
        self._o_did = header.did
        self._o_counter = header.counter
        self._o_issuer = header.syscmd_issuer
        self._o_epoch = header.epoch
        self._o_origin = header.epoch_origin
        consts = sorted((header.offsets[n], v) for n, v in header.consts.items())
        self._const_lo = consts[0][0] if consts else 0
        self._const_hi = consts[-1][0] + 1 if consts else 0
        expected = bytearray(self._const_hi - self._const_lo)
        for offset, value in consts:
            expected[offset - self._const_lo] = value
        if consts and len(consts) != len(expected):
            raise TokenRingError("protocol.yaml: the constant header markers must be adjacent bytes")
        self._const_bytes = bytes(expected)
        self._token_size = protocol.token_size
        self._frame_size = protocol.frame_size
        self._cmd = _Offsets(protocol)

        self._work = bytearray(self._frame_size)
        # what the CRC covers, as a view made once: a new view per pass costs microseconds cold
        self._work_body = memoryview(self._work)[: self._token_size]
        self._token_lock = rt.rlock()
        self._defer_lock = rt.lock()  # the Python path's count of frames handed to the token thread
        self._epoch = 0
        self._origin = 0
        self._accepted_crc = -1
        self._accepted_sid = -1
        self._accepted_frame = b""
        self._has_sent = False
        self._last_sent_did = 0
        self._last_sent_crc = 0
        self._last_sent_time = 0.0
        self._senders: dict[int, Any] = {}
        self._live = self.membership.live  # the same set objects, read on the token path
        self._excluded = self.membership.excluded
        self._hop = self.timing.hop
        self._ack_adaptive = ack_mode == "adaptive"
        self._ack_always = ack_mode == "always"
        self._ack_interval = self.timing.current.ack_interval
        self._rounds_add = self.timing.rounds.add
        self._handler_add = self.timing.handler.add
        self._send_add = self.timing.send.add
        self._ack_pending = False
        self._retries = 0
        self._confirmed_did = 0
        self._confirmed_at = 0.0
        self._recovery_until = 0.0
        self._last_seen = 0.0
        self._last_visit = 0.0
        self._last_counter = -1
        self._exclusion_backoff: dict[int, float] = {}
        # a successor this node skipped that proved alive soon after was only slow (a loaded
        # machine): it gets a longer ack timeout next time, so one slow spell cannot snowball
        # into a storm of exclusions and regenerations (like TCP's backed-off RTO); every pass
        # it acknowledges in time halves the extra again
        self._ack_grace: dict[int, float] = {}
        self._skipped_at: dict[int, float] = {}
        self._regeneration_streak = 0  # own regenerations with no visit in between
        self._live_changed_at = 0.0  # when liveliness last changed (a node came or went)
        self._leaving_nodes: set[int] = set()
        self._started_at = 0.0
        #: how many nodes the launcher is starting: a booting ring waits for all of them (or the
        #: settle cap) before its first token, so it does not circulate among interpreters
        #: that are still importing on the same cores
        self.expected_nodes = expected_nodes
        self._paced = 0.0  # seconds the last pass slept to emulate wire time
        self._stall_wake = 0.0  # when the watchdog last woke far too late

        # user channels
        self._regs: dict[str, DataRegistration] = {}
        self._inbox: Inbox | None = None
        self._outboxes: dict[str, Outbox] = {}
        self._active: tuple[Any, ...] = ()
        self._pending_outboxes: list[Outbox] = []
        self._regs_lock = rt.lock()
        # exactly-once commands: a random incarnation per process, a sequence per target inbox
        # (protocol.yaml, command_channel), and the receiver's memory of what it took, kept by
        # the node so that a restarted program never takes a command twice
        self.incarnation = rt.rng().randrange(1, 1 << 32)
        self._cmd_seqs: dict[str, int] = {}
        self.command_memory = CommandMemory()
        self._visit_waiters = 0
        self._visit_cond = rt.condition(rt.rlock())

        # asks whoever supervises the ring to stop it cleanly (the charger's deep-discharge cut);
        # the node process sets it, in-process rings may leave it None
        self.request_ring_shutdown: Callable[[str], bool] | None = None

        # hooks filled by later layers (system commands, fault injection); the system handler is
        # called at a visit whose token carries a system command (its issuer byte set) or while
        # this node has one to send (system_busy): an idle visit costs no Python call for it
        self.system_handler: Callable[[bytearray], bool] | None = None
        self.system_busy = False
        self.rx_fault: Callable[[bytes], bool] | None = None
        self.tx_fault: Callable[[int, bytearray], bool] | None = None
        self.msg_fault: Callable[[bytes], bool] | None = None
        # --profile: seconds a pass may take after the token arrived (wire + emulated hardware)
        self.pacer: Callable[[float], float] | None = None
        # called (from the program's thread) when a user program raised: the system layer reports it
        self.on_program_error: Callable[[], None] | None = None

        self._joined = False
        self._leaving = False
        self._departed = False  # left with the `leave` fault; `join` brings it back
        self._departure_lock = rt.lock()
        self._rejoin_wanted = False  # `join` came while `depart` was still handing over
        self.paused = False  # set by the soft `hang` fault: the watchdog stands still too
        self._stopping = rt.event()
        self._closing = False  # _stopping as a plain flag for the token path (Event.is_set is Python)
        self._halt = rt.event()  # the current program is being stopped
        self.ring_stopping = False  # the whole ring is shutting down: no handover needed
        # the watchdog sleeps on a raw lock (a C-level binary semaphore): waking it from the
        # token path costs ~0.1 us where threading.Event.set costs tens of microseconds cold
        self._wake_lock = rt.lock()
        self._wake_lock.acquire()
        self._watchdog: Any = None
        self._program: Any = None
        self._program_thread: Any = None
        self._program_set_up = False
        self._program_started = 0.0
        self.program_error: str | None = None

    # =========================================================================================
    # life cycle

    def start(self) -> None:
        """Join the ring: learn who is live, announce this node, start the watchdog."""
        rt = self._rt
        frames = self._frames = rt.simple_queue()
        self._token_thread = rt.spawn(lambda: self._token_loop(frames), f"token-{self.node_id}")
        self._defer = frames.put
        self.transport.active_view = lambda: self.membership.active
        members = self.transport.open(self._on_frame, self._on_message, self._on_membership)
        for member in members:
            self.membership.set_live(member, True)
        for member in members:
            if self._near(member):
                self.transport.prepare(member)
        self.transport.prepare(self.membership.successor)
        now = self._now()
        self._started_at = now
        self._last_seen = now
        self._live_changed_at = now
        self.transport.announce()
        self._joined = True
        self._watchdog = rt.spawn(self._watch, f"watchdog-{self.node_id}")
        log.info(
            "node %s (id %d) joined; live: %s",
            self.name,
            self.node_id,
            sorted(self.membership.live),
        )

    def _token_loop(self, frames: Any) -> None:
        """The token thread: visits the frames the receiving thread handed over, in order."""
        while (frame := frames.get()) is not None:
            try:
                self._visit_frame(frame)
            except Exception:
                log.exception("node %s: the token handler failed", self.name)
            finally:
                self._deferred_done()

    def leave(self, grace: float | None = None) -> None:
        """Leave cleanly and close: a handover, then the transport goes (no handover when the
        whole ring is shutting down: nobody is left to hand over to)."""
        if self._joined and not self._leaving:
            self.stop_program(timeout=0.3 if self.ring_stopping else 1.0)
            if not self.ring_stopping:
                self._handover(grace)
        self.close()

    def depart_in_background(self, grace: float | None = None) -> None:
        """:meth:`depart` on a thread of its own, marked as leaving at once, so that a ``join``
        arriving before the thread runs still finds the departure under way."""
        with self._departure_lock:
            if not self._joined or self._leaving or self._departed:
                return
            self._leaving = True
        self._rt.spawn(lambda: self.depart(grace, True), "fault-leave")

    def depart(self, grace: float | None = None, _marked: bool = False) -> None:
        """Leave the ring but keep the process and its program (the ``leave`` fault)."""
        if self._joined and (_marked or not self._leaving):
            self._handover(grace)
            with self._departure_lock:
                self._departed = True
                self._leaving = False
                come_back, self._rejoin_wanted = self._rejoin_wanted, False
            if come_back:
                self.join()

    def join(self) -> None:
        """Come back after :meth:`depart`: announce liveliness again; the ring inserts us.
        Asked while the departure is still handing over, it comes back once that is done
        (ignored, the node would have stayed out for good: the seeded nemesis found it)."""
        with self._departure_lock:
            if self._closing:  # closed (killed, stopped) while away: nothing to come back to
                return
            if not self._departed:
                if self._leaving:
                    self._rejoin_wanted = True
                return
            self._departed = False
        self._last_seen = self._now()
        self._last_visit = 0.0
        self._last_counter = -1  # rounds went on while we were away, maybe past 128
        self._accepted_crc = -1
        self._accepted_frame = b""
        try:
            self.transport.announce()
        except TokenRingError as exc:  # closed between the check and here
            log.info("node %s stays out: %s", self.name, exc)
            return
        self._announce_rejoin()
        log.info("node %s (id %d) rejoined", self.name, self.node_id)

    def _handover(self, grace: float | None) -> None:
        """Announce the departure (the others route around this node but still accept its
        frames), forward whatever token still arrives until it stops coming, then withdraw."""
        self._leaving = True
        announced = self._now()
        try:
            self.transport.broadcast(
                R.RING_EVENT.pack(R.EVENT_LEAVING, self.node_id, self.node_id, self._epoch, self._origin)
            )
        except TokenRingError as exc:
            log.warning("leaving: %s", exc)
        quiet = max(0.05, 3 * self.timing.rounds.percentile(99, 0.0), 3 * self.timing.hop)
        deadline = self._now() + (grace if grace is not None else 2.0)
        while (now := self._now()) < deadline and not self.ring_stopping:  # it may come late
            if now - announced >= quiet and now - self._last_seen >= quiet:
                break
            self._sleep(min(quiet, 0.02))
        try:
            self.transport.withdraw()
        except TokenRingError as exc:
            log.warning("leaving: %s", exc)

    def close(self) -> None:
        """Stop everything at once (no goodbye); safe to call twice."""
        self._stopping.set()
        self._closing = True
        self._wake()
        self.stop_program()
        if self._watchdog is not None and self._watchdog is not self._rt.current_thread():
            self._watchdog.join(timeout=1.0)
        if self._defer is not None:
            self._frames.put(None)
        try:
            self.transport.close()
        except TokenRingError as exc:
            log.warning("closing transport: %s", exc)
        with self._visit_cond:
            self._visit_cond.notify_all()

    @property
    def stopping(self) -> bool:
        """The node is closing, or the running program was asked to stop: blocking API calls
        (receive_command, deliver, wait_visit) return at once."""
        return self._stopping.is_set() or self._halt.is_set()

    # =========================================================================================
    # the token handler

    # the handler itself (_on_frame, _forward, _transmit, _wake) is the TokenPathBase's: C or
    # Python (tokenring/node/tokenpath.py); what follows are the rare steps both call

    def _answer_stale(self, sid: int, crc: int) -> None:
        """A pass from an older epoch: drop it and tell its sender which token is current."""
        self.stats.stale_tokens += 1
        self._send_message(sid, R.ACK_MESSAGE.pack(b"S", self.node_id, crc, self._epoch, self._origin))

    def _send_failed(self, did: int, exc: BaseException) -> None:
        """A send on the token path raised: count it and log it translated; the watchdog retries."""
        self.stats.send_errors += 1
        error = exc if isinstance(exc, TokenRingError) else self.transport.translate(did, exc)
        log.warning("%s", error)

    def _notify_visit(self) -> None:
        """Wake the threads blocked in :meth:`wait_visit`."""
        with self._visit_cond:
            self._visit_cond.notify_all()

    def _adopt_epoch(self, epoch: int, origin: int, now: float) -> None:
        self._epoch, self._origin = epoch & EPOCH_MASK, origin
        self._last_counter = -1  # a new epoch's token may carry any round (an old copy's)
        self.stats.epoch_changes += 1
        # a newer token exists and is on its way: do not regenerate over it right away
        self._last_seen = max(self._last_seen, now)
        self._recovery_until = now + max(0.02, 2 * self.timing.round_median)

    def _bump_epoch(self, now: float) -> None:
        self._adopt_epoch((self._epoch + 1) & EPOCH_MASK, self.node_id, now)


if NATIVE:

    class _PythonPathNodeOS(PyTokenPath, NodeOS):
        """A node whose token path is the Python one over the C type's state: what
        :meth:`NodeOS.__new__` makes in a simulation (the same steps, on the virtual clock)."""
