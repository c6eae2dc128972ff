"""The node operating system: one token handler per visit, the ring's bookkeeping, the user API.

The handler (``_on_frame``) runs once per token visit, on the transport's receiving thread (or on
the node's token thread while a visit may wait: emulated wire time, a pacer, a fault hook):

1. check the frame (length, CRC-16/ARC, markers, DID, SID a ring member, pass not a repeat,
   epoch not stale) — anything else is dropped and counted, never raised;
2. system commands (a hook filled by :mod:`tokenring.system`); while one is active the user
   channels pause everywhere;
3. the registered, unlocked user channels (data copies, inbox, outgoing commands);
4. where the ring wraps (main) the counter is incremented; the token goes to the successor at once.

Everything slower — timeouts, retries, regeneration, statistics — happens on a watchdog thread
off that path. User programs run in their own thread and talk to the handler only through
:class:`~tokenring.channels.ChannelBuffer` objects and a few flags.
"""

from __future__ import annotations

import logging
import os
import queue
import random
import socket
import threading
import time
import traceback
from collections.abc import Callable
from typing import Any

from tokenring import ring as R
from tokenring.channels import (
    ChannelBuffer,
    CommandMemory,
    DataRegistration,
    Inbox,
    Outbox,
    ReceivedCommand,
    _Offsets,
)
from tokenring.errors import ChannelError, TokenRingError
from tokenring.protocol import Channel, CommandChannel, Protocol
from tokenring.ring import EPOCH_MASK
from tokenring.tokenpath import TokenPathBase, TokenPathHost
from tokenring.transport.base import Transport

log = logging.getLogger("tokenring.node")

#: a watchdog that overslept this long (and 4 reconfiguration times) was frozen, e.g. SIGSTOP;
#: shorter gaps happen on any loaded machine and must not make the node ask to rejoin
FROZEN_AFTER_S = 1.0
FALSE_EXCLUSION_S = 2.0  # a skipped successor alive again within this was slow, not dead
ACK_GRACE_MAX = 8.0  # its ack timeout grows at most this many times
PREPARED_NEIGHBOURS = 8  # live nodes either side whose token and ack paths are declared ahead
SETTLE_RECONS = 2  # a booting ring starts this many reconfiguration times after the last join
SETTLE_CAP_S = 30.0  # ... but at the latest this long (or 0.5 s per live node) after boot
EXPECT_CAP_S = 5.0  # a ring told how many nodes boot waits for them this long (or 0.5 s each)
LATECOMER_RECONS = 10  # how many reconfiguration times a booting node waits for main's token
REGENERATION_BACKOFF_MAX = 7  # reconfiguration times added after fruitless regenerations
#: how often a node pings an excluded node that is not among its neighbours: only the nodes
#: that would pass to it need to find out quickly that it is back (at 255 nodes, every node
#: pinging every excluded node ten times a second, each answer re-announced to all, is a storm)
FAR_PROBE_S = 2.0
#: the watchdog's timeout refresh waits up to this long for a wake it has anyway (a pass's ack
#: timer, the token-loss timer) instead of waking for it alone: at 64 nodes the watchdogs' wakes
#: cost the ring ~20 µs of CPU per hop on two cores, at 255 ~16 µs after the first cut
REFRESH_SLACK_S = 1.5
#: the watchdog sleeps at most this many reconfiguration times, so a missed wake costs no more
WATCH_MAX_SLEEP_RECONS = 4.0
perf_counter = time.perf_counter


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
    __slots__ = FIELDS
    frames_received: int
    frames_sent: int
    rejected_length: int
    rejected_crc: int
    rejected_marker: int
    rejected_did: int
    rejected_sid: int
    duplicate_passes: int
    stale_tokens: int
    replayed_passes: int
    rounds: int
    rounds_missed: int
    visits: int
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
        for name in self.FIELDS:
            setattr(self, name, 0)

    def as_dict(self) -> dict[str, int]:
        return {name: getattr(self, name) for name in self.FIELDS}


class NodeOS(TokenPathBase, TokenPathHost):
    """One node of the ring: the token handler, ring membership and the user-program API."""

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
        self.protocol = protocol
        self.node_id = node_id
        self.transport = transport
        spec = protocol.by_id.get(node_id)
        self.spec = spec
        self.name = name or (spec.name if spec else f"node{node_id}")
        self.stats = NodeStats()
        self.timing = R.Timing(bitrate, ack_mode)
        self.membership = R.Membership(node_id)
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
        self._token_lock = threading.RLock()
        self._epoch = 0
        self._origin = 0
        self._accepted_crc = -1
        self._accepted_sid = -1
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
        self._regs_lock = threading.Lock()
        # exactly-once commands: a random incarnation per process, a sequence per target inbox
        # (protocol.yaml, command_channel), and the receiver's memory of what it took, kept by
        # the node so that a restarted program never takes a command twice
        self.incarnation = random.SystemRandom().randrange(1, 1 << 32)
        self._cmd_seqs: dict[str, int] = {}
        self.command_memory = CommandMemory()
        self._visit_waiters = 0
        self._visit_cond = threading.Condition()

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
        self._departure_lock = threading.Lock()
        self._rejoin_wanted = False  # `join` came while `depart` was still handing over
        self.paused = False  # set by the soft `hang` fault: the watchdog stands still too
        self._stopping = threading.Event()
        self._closing = False  # _stopping as a plain flag for the token path (Event.is_set is Python)
        self._halt = threading.Event()  # the current program is being stopped
        self.ring_stopping = False  # the whole ring is shutting down: no handover needed
        # the watchdog sleeps on a raw lock (a C-level binary semaphore): waking it from the
        # token path costs ~0.1 us where threading.Event.set costs tens of microseconds cold
        self._wake_lock = threading.Lock()
        self._wake_lock.acquire()
        self._watchdog: threading.Thread | None = None
        self._program: Any = None
        self._program_thread: threading.Thread | None = None
        self.program_error: str | None = None

    # =========================================================================================
    # life cycle

    def start(self) -> None:
        """Join the ring: learn who is live, announce this node, start the watchdog."""
        self._frames: queue.SimpleQueue[bytes | None] = queue.SimpleQueue()
        self._token_thread = threading.Thread(
            target=self._token_loop, args=(self._frames,), name=f"token-{self.node_id}", daemon=True
        )
        self._token_thread.start()
        self._defer = self._frames.put
        members = self.transport.open(self._on_frame, self._on_message, self._on_membership)
        for member in members:
            self.membership.set_live(member, True)
        for member in members:
            if self._near(member):
                self.transport.prepare(member)
        self.transport.prepare(self.membership.successor)
        now = perf_counter()
        self._started_at = now
        self._last_seen = now
        self._live_changed_at = now
        self.transport.announce()
        self._joined = True
        self._watchdog = threading.Thread(target=self._watch, name=f"watchdog-{self.node_id}", daemon=True)
        self._watchdog.start()
        log.info(
            "node %s (id %d) joined; live: %s",
            self.name,
            self.node_id,
            sorted(self.membership.live),
        )

    def _token_loop(self, frames: queue.SimpleQueue[bytes | None]) -> None:
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
        threading.Thread(target=self.depart, args=(grace, True), name="fault-leave", daemon=True).start()

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
            if not self._departed:
                if self._leaving:
                    self._rejoin_wanted = True
                return
            self._departed = False
        self._last_seen = perf_counter()
        self._last_visit = 0.0
        self._last_counter = -1  # rounds went on while we were away, maybe past 128
        self._accepted_crc = -1
        self.transport.announce()
        self._announce_rejoin()
        log.info("node %s (id %d) rejoined", self.name, self.node_id)

    def _handover(self, grace: float | None) -> None:
        """Announce the departure (the others route around this node but still accept its
        frames), forward whatever token still arrives until it stops coming, then withdraw."""
        self._leaving = True
        announced = perf_counter()
        try:
            self.transport.broadcast(
                R.RING_EVENT.pack(R.EVENT_LEAVING, self.node_id, self.node_id, self._epoch, self._origin)
            )
        except TokenRingError as exc:
            log.warning("leaving: %s", exc)
        quiet = max(0.05, 3 * self.timing.rounds.percentile(99, 0.0), 3 * self.timing.hop)
        deadline = time.monotonic() + (grace if grace is not None else 2.0)
        while time.monotonic() < deadline:
            now = perf_counter()
            if now - announced >= quiet and now - self._last_seen >= quiet:
                break
            time.sleep(min(quiet, 0.02))
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
        if self._watchdog is not None and self._watchdog is not threading.current_thread():
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
    # Python (tokenring/tokenpath.py); what follows are the rare steps both call

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

    # =========================================================================================
    # messages, membership and the watchdog

    def _send_ack(self, did: int, crc: int) -> None:
        self._send_message(did, R.ACK_MESSAGE.pack(b"A", self.node_id, crc, self._epoch, self._origin))

    def _send_message(self, did: int, payload: bytes) -> None:
        try:
            self.transport.send_message(did, payload)
        except TokenRingError as exc:
            log.debug("message to %d: %s", did, exc)

    def _on_message(self, payload: bytes) -> None:
        if self.msg_fault is not None and self.msg_fault(payload):
            return
        if self._departed:
            return
        kind = payload[:1]
        if kind == b"P":  # an excluded node is pinged: answering brings it back
            if len(payload) == R.ACK_MESSAGE.size:
                self._send_message(
                    payload[1], R.ACK_MESSAGE.pack(b"A", self.node_id, 0, self._epoch, self._origin)
                )
            return
        if kind in (b"A", b"S"):
            if len(payload) != R.ACK_MESSAGE.size:
                return
            _, sender, crc, epoch, origin = R.ACK_MESSAGE.unpack(payload)
            now = perf_counter()
            if sender in self._excluded:
                self._include(sender, tell=True)  # it answers: it is alive after all
            if kind == b"S" and R.epoch_order(epoch, origin, self._epoch, self._origin) > 0:
                # our token is the stale one (e.g. a partition healed): learn the newer epoch and
                # tell everyone, so the old token dies everywhere and this side rejoins
                self._adopt_epoch(epoch, origin, now)
                self.stats.stale_tokens += 1
                self._announce_rejoin()
            with self._token_lock:
                if sender == self._last_sent_did and crc == self._last_sent_crc:
                    if self._ack_pending:
                        self.timing.ack_latency.add(now - self._last_sent_time)
                        self.stats.passes_acked += 1
                        if sender in self._ack_grace:  # answering in time again: shrink it back
                            grace = self._ack_grace.pop(sender) / 2
                            if grace > 1.0:
                                self._ack_grace[sender] = grace
                    self._ack_pending = False
                    self._retries = 0
                    self._confirmed_did = sender
                    self._confirmed_at = now
            return
        if len(payload) != R.RING_EVENT.size:
            return
        kind, node_id, by, epoch, origin = R.RING_EVENT.unpack(payload)
        # only events about tokens teach epochs: a rejoin is about membership, and after a
        # partition heals both sides' tokens must simply meet (the older dies where it meets
        # a node that has seen the newer) instead of each side killing the other's by event
        learns_epoch = kind in (R.EVENT_EXCLUDED, R.EVENT_REGENERATED)
        if (
            learns_epoch
            and by != self.node_id
            and R.epoch_order(epoch, origin, self._epoch, self._origin) > 0
        ):
            self._adopt_epoch(epoch, origin, perf_counter())
        if kind == R.EVENT_EXCLUDED and by != self.node_id:
            if node_id == self.node_id:
                log.warning("excluded from the ring by node %d; asking to rejoin", by)
                self._announce_rejoin()
            elif self.membership.exclude(node_id, self._backoff(node_id)):
                self._successor_changed()
        elif kind == R.EVENT_REJOIN and node_id != self.node_id:
            self._include(node_id)
        elif kind == R.EVENT_RING_STOPPING:
            self.ring_stopping = True
        elif kind == R.EVENT_REGENERATED and by != self.node_id:
            self._last_seen = max(self._last_seen, perf_counter())  # a fresh token is on its way
        elif kind == R.EVENT_LEAVING and node_id != self.node_id:
            # route around it at once, but keep accepting its frames until it withdraws
            self._leaving_nodes.add(node_id)
            if self.membership.exclude(node_id, retry_after=60.0):
                self._successor_changed()

    def _announce_rejoin(self) -> None:
        try:
            self.transport.broadcast(
                R.RING_EVENT.pack(R.EVENT_REJOIN, self.node_id, self.node_id, self._epoch, self._origin)
            )
        except TokenRingError as exc:
            log.debug("rejoin: %s", exc)

    def _backoff(self, node_id: int) -> float:
        """How long until an excluded node is pinged (again): 0.05 s, then every 0.1 s by its
        neighbours (a ping is a few bytes, so a healed partition merges within a tenth of a
        second or two), every :data:`FAR_PROBE_S` by everyone else."""
        if not self._near(node_id):
            self._exclusion_backoff[node_id] = FAR_PROBE_S
            return FAR_PROBE_S
        previous = self._exclusion_backoff.get(node_id, 0.025)
        value = min(0.1, previous * 2)
        self._exclusion_backoff[node_id] = value
        return value

    def _include(self, node_id: int, tell: bool = False) -> None:
        """Take an excluded node back; ``tell`` broadcasts it (we saw it alive ourselves)."""
        if node_id in self._leaving_nodes:
            return  # it still answers while it hands over, but it is on its way out
        self._exclusion_backoff.pop(node_id, None)
        skipped_at = self._skipped_at.pop(node_id, None)
        if skipped_at is not None and perf_counter() - skipped_at < FALSE_EXCLUSION_S:
            self._ack_grace[node_id] = min(ACK_GRACE_MAX, 2 * self._ack_grace.get(node_id, 1.0))
            self.stats.successors_only_slow += 1
        if self.membership.include(node_id):
            self._successor_changed()
            if tell:
                try:
                    self.transport.broadcast(
                        R.RING_EVENT.pack(R.EVENT_REJOIN, node_id, self.node_id, self._epoch, self._origin)
                    )
                except TokenRingError as exc:
                    log.debug("rejoin event: %s", exc)

    def _on_membership(self, node_id: int, alive: bool) -> None:
        if node_id == self.node_id:
            return
        changed = self.membership.set_live(node_id, alive)
        self._live_changed_at = perf_counter()
        if alive:
            self._leaving_nodes.discard(node_id)
            if self._near(node_id):
                self.transport.prepare(node_id)
        else:
            self._senders.pop(node_id, None)
        if changed:
            self._successor_changed()
        if not alive:
            self._lost_member(node_id)
            self._leaving_nodes.discard(node_id)
        self._wake()  # the regeneration deadline depends on who is live

    def _near(self, node_id: int) -> bool:
        """Whether ``node_id`` is among the next or previous :data:`PREPARED_NEIGHBOURS` live
        nodes: the ones this node passes to or acknowledges after a skip. Their paths are
        declared ahead; anyone else's on first use (255 nodes declaring paths to all others
        would be 65 000 declarations through one router)."""
        live = sorted(self.membership.live)
        if len(live) <= 2 * PREPARED_NEIGHBOURS + 1 or node_id not in live:
            return True
        distance = (live.index(node_id) - live.index(self.node_id)) % len(live)
        return distance <= PREPARED_NEIGHBOURS or distance >= len(live) - PREPARED_NEIGHBOURS

    def _lost_member(self, node_id: int) -> None:
        """A node vanished (crash or leave). If our last pass went to it, pass again."""
        if self._stopping.is_set():
            return
        with self._token_lock:
            if (
                node_id != self._last_sent_did
                or node_id in self._leaving_nodes
                or not self._has_sent
                or self._last_visit > self._last_sent_time
                or self._leaving
            ):
                return
            log.info("node %d vanished holding our last pass; passing again", node_id)
            self.stats.reconfigurations += 1
            self._repass(perf_counter())

    def _repass(self, now: float) -> None:
        """Send our last copy of the token (still in the working buffer) on, in a new epoch."""
        self._bump_epoch(now)
        self._forward(now)

    def _successor_changed(self) -> None:
        # no Zenoh declaration here: this runs under the token lock, and a declaration goes to
        # every peer with blocking congestion control — behind a cut link it can block for
        # seconds. Publishers are declared when a node becomes live (_on_membership).
        self.stats.successor_changes += 1
        self._wake()  # this node's rank, and so its regeneration deadline, may have changed

    def _watch(self) -> None:
        refresh_at = 0.0
        planned = perf_counter()  # when this loop meant to run next
        while not self._stopping.is_set():
            if self.paused or self._departed:
                self._wake_lock.acquire(timeout=0.05)
                continue
            now = perf_counter()
            self.stats.watchdog_wakes += 1
            if now - planned > max(FROZEN_AFTER_S, 4 * self.timing.current.recon):
                # this process was frozen (SIGSTOP, a long pause): whatever we hold is old; ask
                # to rejoin and give the ring one reconfiguration time before regenerating
                log.warning("woke up after %.1f s frozen; asking to rejoin", now - planned)
                with self._token_lock:
                    self._ack_pending = False
                    self._last_seen = now
                self._announce_rejoin()
            if now >= refresh_at or self.timing.due():
                # live, not active: exclusions must not shrink the timeouts that caused them
                self._ack_interval = self.timing.refresh(len(self.membership.live)).ack_interval
                refresh_at = now + (0.1 if now - self._started_at < 3.0 else 0.5)
                for node_id in self.membership.probes_due(time.monotonic(), self._exclusion_backoff):
                    # a ping, not the token: a node that is still hung costs the ring nothing
                    self._send_message(
                        node_id, R.ACK_MESSAGE.pack(b"P", self.node_id, 0, self._epoch, self._origin)
                    )
                    self._backoff(node_id)
            timeouts = self.timing.current
            # probing excluded nodes keeps its pace; otherwise the refresh may ride on a later wake
            deadlines = [refresh_at if self.membership.excluded else refresh_at + REFRESH_SLACK_S]
            with self._token_lock:
                if self._ack_pending:
                    due = self._last_sent_time + timeouts.ack * self._ack_grace.get(self._last_sent_did, 1.0)
                    if now >= due:
                        self._pass_timed_out(now)
                    else:
                        deadlines.append(due)
            if now - planned > timeouts.slot:
                # woke far too late (a loaded machine stalled us): every deadline may have
                # passed at once, so restart the rank stagger from now; higher ranks go first
                self._stall_wake = now
            if self._joined and not self._leaving and not self._departed:
                due = self._regeneration_deadline(timeouts)
                if now >= due:
                    self._regenerate(now)
                else:
                    deadlines.append(due)
            # sleep until the earliest deadline: whatever moves one earlier (a membership
            # change, the token back after regenerations, a pass wanting an ack) wakes us
            wait = max(0.0, min(min(deadlines) - perf_counter(), WATCH_MAX_SLEEP_RECONS * timeouts.recon))
            planned = perf_counter() + wait
            self._wake_lock.acquire(timeout=wait)

    def _regeneration_deadline(self, timeouts: R.Timeouts) -> float:
        booting = self._last_visit == 0.0 and not self._has_sent
        # while nodes are still coming up (liveliness keeps changing), the ring is not started:
        # as on ARCNET, where every join reconfigures, a ring that starts circulating while a
        # hundred more interpreters boot on the same cores would only reconfigure again and again
        live = len(self.membership.live)
        settled = self._live_changed_at + SETTLE_RECONS * timeouts.recon
        settled = min(settled, self._started_at + max(SETTLE_CAP_S, 0.5 * live))
        if booting and self.expected_nodes and live < self.expected_nodes:
            # the launcher is still starting nodes (one that died at boot costs this much)
            settled = self._started_at + max(EXPECT_CAP_S, 0.5 * self.expected_nodes)
        if booting and self.preferred_master == self.node_id:
            # main starts the ring: wait briefly for a token that may already circulate
            return max(settled, self._started_at + max(0.15, 4 * timeouts.hop * len(self.membership.active)))
        # a watchdog that overslept was starved with the rest of the machine: the token is as
        # late as it was, so even the highest rank gives it one slot after waking
        lost_since = max(self._last_seen + timeouts.recon, self._stall_wake + timeouts.slot)
        if self._deferred_pending:
            # a frame already waits for this node's token thread (taken off the wire, not yet
            # visited): the token is here and late, not lost - look again a slot later
            lost_since = max(lost_since, perf_counter() + timeouts.slot)
        # a token this node regenerated that never came back: wait longer each time (a slow
        # ring is still forming around it), as Ethernet backs off after collisions
        streak = max(0, self._regeneration_streak - 1)  # a second try is normal recovery
        backoff = timeouts.recon * min(2**streak - 1, REGENERATION_BACKOFF_MAX)
        deadline = lost_since + self.membership.rank() * timeouts.slot + backoff
        if booting:
            deadline = max(deadline, settled + self.membership.rank() * timeouts.slot)
            if self.preferred_master in self._live:
                # main is up and has started (or will start) the token: a node joining a big
                # ring on a busy machine may wait seconds before its predecessor routes it here
                deadline += max(1.0, LATECOMER_RECONS * timeouts.recon)
        return deadline

    def _pass_timed_out(self, now: float) -> None:
        """No acknowledgement in time: retry the same pass, then declare the successor dead."""
        did = self._last_sent_did
        self.stats.unacked_passes += 1
        if self._retries < R.ACK_RETRIES:
            self._retries += 1
            self.stats.pass_retries += 1
            self._last_sent_time = now
            self._transmit(did)  # the working buffer still holds the frame, bit for bit
            return
        self._ack_pending = False
        self.stats.successors_declared_dead += 1
        self.stats.reconfigurations += 1
        log.warning("successor %d did not acknowledge %d passes; skipping it", did, R.ACK_RETRIES + 1)
        self._skipped_at[did] = now
        if self.membership.exclude(did, self._backoff(did)):
            self._successor_changed()
        self._bump_epoch(now)
        try:
            self.transport.broadcast(
                R.RING_EVENT.pack(R.EVENT_EXCLUDED, did, self.node_id, self._epoch, self._origin)
            )
        except TokenRingError as exc:
            log.debug("exclude event: %s", exc)
        self._forward(now)

    def _regenerate(self, now: float) -> None:
        """No token seen for the reconfiguration timeout: this node restarts the ring."""
        with self._token_lock:
            recon = self.timing.current.recon
            if self._last_visit and perf_counter() - self._last_seen < recon:
                return
            first = self._last_visit == 0.0 and not self._has_sent
            self.stats.tokens_regenerated += 1
            if not first:
                self._regeneration_streak += 1
            if not first:
                self.stats.reconfigurations += 1
                log.warning(
                    "no token for %.0f ms: regenerating it (rank %d)",
                    (now - self._last_seen) * 1e3,
                    self.membership.rank(),
                )
            self._bump_epoch(now)
            if not first:
                try:
                    self.transport.broadcast(
                        R.RING_EVENT.pack(
                            R.EVENT_REGENERATED, self.node_id, self.node_id, self._epoch, self._origin
                        )
                    )
                except TokenRingError as exc:
                    log.debug("regeneration event: %s", exc)
            if first:  # the seed: main initialises the token with zeros
                work = self._work
                work[:] = bytes(self._frame_size)
                for offset in range(self._const_lo, self._const_hi):
                    work[offset] = self._const_bytes[offset - self._const_lo]
            self._last_seen = now
            self._forward(now)

    # =========================================================================================
    # the user-program API (the seed's calls, in Pythonic form)

    def channel(self, name: str) -> Channel:
        """A channel by ``node.kind``, seed name (``ROBSONAR_DATA``) or, for inboxes, node name."""
        if name in self.protocol.nodes:
            return self.protocol.nodes[name].command
        return self.protocol.channel(name)

    def set_token_area(self, channel: str, address: int | None = None) -> Channel:
        """Seed call; addresses come from protocol.yaml, so this only checks they agree."""
        ch = self.channel(channel)
        if address is not None and address != ch.address:
            raise ChannelError(f"{ch.name} lives at byte {ch.address} per protocol.yaml, not {address}")
        return ch

    def set_own_input_id(self, channel: str | None = None) -> None:
        """Declare this node's own command channel (default: the one protocol.yaml gives it)."""
        ch = self.channel(channel) if channel else (self.spec.command if self.spec else None)
        if not isinstance(ch, CommandChannel):
            raise ChannelError(f"{channel!r} is not a command channel")
        if self.spec is not None and ch.name != self.spec.command.name:
            raise ChannelError(f"{ch.name} belongs to {ch.node}, not to {self.name}")
        with self._regs_lock:
            if self._inbox is None or self._inbox.channel is not ch:
                self._inbox = Inbox(ch, self._cmd, self.membership.live, self.stats, self.command_memory)
            self._rebuild_active()

    def get_data(self, channel: str, owner: str = "program") -> ChannelBuffer:
        """Copy ``channel`` out of the token at every visit (once unlocked); returns the buffer.

        ``owner="os"`` marks a registration of an OS service (the PC link) that outlives the
        user program; the program's own registrations are dropped when it stops."""
        ch = self.channel(channel)
        if isinstance(ch, CommandChannel):
            if self.spec is not None and ch.node == self.spec.name:
                self.set_own_input_id(ch.name)
                assert self._inbox is not None
                return self._inbox.buffer
            raise ChannelError(f"{ch.name} is another module's inbox: use send_command")
        return self._register(ch, "get", owner)

    def store_data(self, channel: str) -> ChannelBuffer:
        """Copy the returned buffer into ``channel`` at every visit (once unlocked)."""
        ch = self.channel(channel)
        if isinstance(ch, CommandChannel):
            raise ChannelError(f"{ch.name} is a command channel: use send_command")
        if self.spec is not None and ch.node != self.spec.name:
            raise ChannelError(f"{ch.name} belongs to {ch.node}; only its owner may store into it")
        return self._register(ch, "store", "program")

    def _register(self, ch: Channel, kind: str, owner: str) -> ChannelBuffer:
        with self._regs_lock:
            reg = self._regs.get(ch.name)
            if reg is None or reg.kind != kind:
                reg = DataRegistration(ch, kind, ChannelBuffer(ch), owner)
                self._regs[ch.name] = reg
                self._rebuild_active()
            elif owner == "program":
                reg.owner = "program"  # shared with an OS service: the program now holds it too
            return reg.buffer

    def lock_data(self, channel: str) -> None:
        """Stop copying this channel (the seed's semaphore)."""
        self._set_locked(channel, True)

    def unlock_data(self, channel: str) -> None:
        """Resume copying this channel; for the own inbox: ready to receive the next command."""
        self._set_locked(channel, False)

    def _set_locked(self, channel: str, locked: bool) -> None:
        ch = self.channel(channel)
        with self._regs_lock:
            if self._inbox is not None and ch.name == self._inbox.channel.name:
                if not locked:
                    self._inbox.received = False
                    self._inbox.event.clear()
                self._inbox.locked = locked
                return
            reg = self._regs.get(ch.name)
            if reg is None:
                raise ChannelError(
                    f"{ch.name} is not registered on {self.name}: call get_data/store_data first"
                )
            reg.locked = locked
            self._rebuild_active()

    def cancel_data(self, channel: str) -> None:
        """Remove a registration."""
        ch = self.channel(channel)
        with self._regs_lock:
            if self._inbox is not None and ch.name == self._inbox.channel.name:
                self._inbox = None
            else:
                self._regs.pop(ch.name, None)
            self._rebuild_active()

    def subscribe(self, channel: str, owner: str = "program") -> ChannelBuffer:
        """get_data + unlock_data in one call."""
        buffer = self.get_data(channel, owner)
        self.unlock_data(channel)
        return buffer

    def publish(self, channel: str | None = None) -> ChannelBuffer:
        """store_data + unlock_data of this node's own data channel (or ``channel``)."""
        name = channel or (self.spec.data.name if self.spec else "")
        buffer = self.store_data(name)
        self.unlock_data(name)
        return buffer

    def send_command(self, target: str, command: str | int, **args: Any) -> Outbox:
        """Queue a command for another module's inbox; the OS writes it when the inbox is free."""
        ch = self.channel(target)
        if not isinstance(ch, CommandChannel):
            raise ChannelError(f"{ch.name} is not a command channel")
        cmd = ch.command(command)
        # token lock first (the handler's order): a waiting outbox is never replaced mid-visit
        with self._token_lock, self._regs_lock:
            current = self._outboxes.get(ch.name)
            if current is not None and current.state == Outbox.IN_TOKEN:
                raise ChannelError(f"a command to {ch.name} is still travelling; wait for it first")
            if current is not None:
                current.cancel()
            seq = self._cmd_seqs[ch.name] = (self._cmd_seqs.get(ch.name, 0) + 1) & 0xFFFF
            outbox = Outbox(ch, cmd, self._cmd, self.node_id, seq, args, self.stats, self.incarnation)
            self._outboxes[ch.name] = outbox
            self._pending_outboxes.append(outbox)
        return outbox

    def _sweep_own_commands(self, work: bytearray) -> None:
        """After a regeneration from an old copy, clear our own finished commands from it."""
        off = self._cmd
        for outbox in tuple(self._outboxes.values()):
            a = outbox.start
            if (
                outbox.state == Outbox.DONE
                and work[a + off.sender] == self.node_id
                and work[a + off.state] != off.FREE
            ):
                work[a : outbox.end] = bytes(outbox.end - a)
                self.stats.stale_commands_cleared += 1

    def _activate_outboxes(self) -> None:
        with self._regs_lock:
            self._rebuild_active()

    def _drop_outboxes(self, finished: list[Any]) -> None:
        with self._regs_lock:
            self._rebuild_active(exclude=finished)

    def _rebuild_active(self, exclude: list[Any] | None = None) -> None:
        """Recompute what the handler visits (caller holds the registration lock)."""
        items: list[Any] = [r for r in self._regs.values() if not r.locked]
        if self._inbox is not None:
            items.append(self._inbox)
        items.extend(
            o
            for o in self._outboxes.values()
            if o.state != Outbox.DONE and (exclude is None or o not in exclude)
        )
        self._active = tuple(items)
        self._pending_outboxes = []

    def command_transmitted(self, target: str) -> bool:
        """The last command to ``target`` was written into the token and came back."""
        outbox = self._outboxes.get(self.channel(target).name)
        return bool(outbox and outbox.transmitted)

    def command_acknowledged(self, target: str) -> bool:
        """... and the receiver's OS copied it into its structure."""
        outbox = self._outboxes.get(self.channel(target).name)
        return bool(outbox and outbox.acknowledged)

    def command_received(self, channel: str | None = None) -> bool:
        """Has a command arrived in this node's inbox (which is now locked)?"""
        return bool(self._inbox and self._inbox.received)

    def get_command(self) -> ReceivedCommand:
        """Decode the command in the inbox (call unlock_data on the inbox for the next one)."""
        if self._inbox is None or not self._inbox.received:
            raise ChannelError(f"no command received on {self.name}")
        return self._inbox.take()

    def receive_command(self, timeout: float | None = None) -> ReceivedCommand | None:
        """Wait for the next command, take it and reopen the inbox; None on timeout or stop."""
        inbox = self._inbox
        if inbox is None:
            self.set_own_input_id()
            inbox = self._inbox
            assert inbox is not None
        if inbox.locked and not inbox.received:
            self.unlock_data(inbox.channel.name)
        deadline = None if timeout is None else time.monotonic() + timeout
        while not inbox.received:
            if self.stopping:
                return None
            remaining = 0.1 if deadline is None else min(0.1, deadline - time.monotonic())
            if remaining <= 0:
                return None
            inbox.event.wait(remaining)
        received = inbox.take()
        self.unlock_data(inbox.channel.name)
        return received

    def deliver(self, target: str, command: str | int, *, timeout: float = 5.0, **args: Any) -> bool:
        """Send until acknowledged (resending after each unacknowledged round) or timeout."""
        deadline = time.monotonic() + timeout
        self.wait_channel_free(target, timeout)
        while not self.stopping:
            outbox = self.send_command(target, command, **args)
            while not outbox.done.wait(0.05):
                if self.stopping or time.monotonic() > deadline:
                    outbox.cancel()
                    return False
            if outbox.acknowledged:
                return True
            if time.monotonic() > deadline:
                return False
            time.sleep(min(0.002, max(0.0, deadline - time.monotonic())))
        return False

    def wait_channel_free(self, target: str, timeout: float) -> bool:
        """Wait until no earlier command of ours to ``target`` is still travelling."""
        outbox = self._outboxes.get(self.channel(target).name)
        if outbox is None or outbox.state != Outbox.IN_TOKEN:
            return True
        return outbox.done.wait(timeout)

    def wait_visit(self, timeout: float | None = None) -> bool:
        """Block until the token's next visit; False on timeout or stop."""
        with self._visit_cond:
            self._visit_waiters += 1
            try:
                before = self.stats.visits
                ok = self._visit_cond.wait_for(lambda: self.stats.visits != before or self.stopping, timeout)
                return bool(ok) and not self.stopping
            finally:
                self._visit_waiters -= 1

    @property
    def counter(self) -> int:
        """The token counter seen at the last visit."""
        return max(self._last_counter, 0)

    # =========================================================================================
    # user programs

    def start_program(self, program_class: type, *args: Any) -> None:
        """Instantiate and run a user program in its own thread (``setup`` then ``run``)."""
        self.stop_program()
        self._halt.clear()
        self.program_error = None
        program = program_class(self, *args)
        self._program = program

        def runner() -> None:
            try:
                program.setup()
                program.run()
            except Exception as exc:  # a user program's bug must not take the node down
                last = traceback.format_exception_only(type(exc), exc)[-1].strip()
                self.program_error = last
                log.error("user program %s failed: %s", type(program).__name__, last)
                log.debug("traceback:\n%s", traceback.format_exc())
                if self.on_program_error is not None:
                    self.on_program_error()
            finally:
                try:
                    program.teardown()
                except Exception as exc:
                    log.error("user program teardown failed: %s", exc)

        self._program_thread = threading.Thread(target=runner, name=f"program-{self.name}", daemon=True)
        self._program_thread.start()

    def stop_program(self, timeout: float = 1.0) -> bool:
        """Ask the running program to stop, wait for it, drop its registrations."""
        program, thread = self._program, self._program_thread
        if program is None:
            return True
        program.stop_requested.set()
        self._halt.set()
        with self._visit_cond:
            self._visit_cond.notify_all()
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout)
        stopped = thread is None or not thread.is_alive()
        if not stopped:
            log.warning("user program %s did not stop within %.1f s", type(program).__name__, timeout)
        with self._regs_lock:
            self._regs = {k: r for k, r in self._regs.items() if r.owner != "program"}
            self._inbox = None
            for outbox in self._outboxes.values():
                if outbox.state == Outbox.WAITING:
                    outbox.cancel()
            self._rebuild_active()
        self._program = None
        self._program_thread = None
        self._halt.clear()  # only the stopping program's blocking calls were to return early
        return stopped

    @property
    def program(self) -> Any:
        return self._program

    # =========================================================================================
    # introspection

    def snapshot(self) -> dict[str, Any]:
        """Counters, membership and timing for ``stats`` queries, the monitor and benchmarks."""
        timing = self.timing
        t = timing.current
        rounds = timing.rounds.recent(512)  # recent: a status must follow what happens now
        handler = timing.handler.recent(512)
        send = timing.send.recent(512)

        def pct(values: Any, q: float) -> float:
            import numpy as np

            return float(np.percentile(values, q) * 1e3) if len(values) else 0.0

        return {
            "id": self.node_id,
            "name": self.name,
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "epoch": [self._epoch, self._origin],
            "counter": self.counter,
            "master": min(self.membership.active),
            "successor": self.membership.successor,
            "live": sorted(self.membership.live),
            "active": list(self.membership.active),
            "excluded": sorted(self.membership.excluded),
            "stats": self.stats.as_dict(),
            "timeouts_ms": {
                "hop": t.hop * 1e3,
                "ack": t.ack * 1e3,
                "recon": t.recon * 1e3,
                "slot": t.slot * 1e3,
                "ack_interval": t.ack_interval * 1e3,
            },
            "round_ms": {"median": pct(rounds, 50), "p99": pct(rounds, 99), "n": len(rounds)},
            "handler_us": {
                "median": pct(handler, 50) * 1e3,
                "p99": pct(handler, 99) * 1e3,
                "n": len(handler),
            },
            "send_us": {"median": pct(send, 50) * 1e3, "p99": pct(send, 99) * 1e3},
            "program": type(self._program).__name__ if self._program is not None else None,
            "program_error": self.program_error,
            "bitrate": timing.bitrate,
            "ack_mode": timing.ack_mode,
        }

    def round_times(self) -> list[float]:
        """Seconds between this node's last visits (up to 1024)."""
        return self.timing.rounds.values().tolist()
