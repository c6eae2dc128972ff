"""The token path: the handler that runs once per token visit, native or in Python.

:class:`~tokenring.node.node_os.NodeOS` inherits the handler (``_on_frame``), the pass (``_forward``)
and the send (``_transmit``) from :data:`TokenPathBase`: the C type of
``tokenring/_tokenpath.c`` when it was compiled at install, else :class:`PyTokenPath` below,
the same steps in Python. Both keep the ring's state in the same attributes, so the watchdog,
the acks and the user API (all Python) read and write it alike; everything rare (a stale
epoch, an excluded sender, a leaving node, hooks, commands, a failed send) calls the same
Python methods of the node from either. ``TOKENRING_NATIVE=0`` picks the Python path;
``tests/ring/node/test_tokenpath.py`` runs one scenario through both and compares every byte sent.

The Python path reads the clock and sleeps through the node's runtime (``_now``, ``_sleep``,
bound once by the node), so a simulation runs it on its virtual clock; the C path reads the OS's
clock itself, which is why a simulated node runs the Python path.

``_on_frame`` is the receiving thread's entry: it visits at once, or hands the frame to the
node's token thread while the visit may wait (see its docstring). The visit (``_visit_frame``;
see :mod:`tokenring.node` for what each step means):

1. check the frame (length, CRC-16/ARC, markers, DID, SID a ring member, pass not a repeat,
   epoch not stale, round newer than the last in this epoch) — anything else is dropped and
   counted, never raised;
2. system commands (``system_handler``; skipped while no command is anywhere: the issuer byte
   is clear and the node's ``system_busy`` is not set);
3. the registered, unlocked user channels (data copies, inbox, outgoing commands);
4. the counter where the ring wraps, then seal and pass the token to the successor at once;
   the bookkeeping (round and handler times, counters, the pass's ack) comes after the put.
"""

from __future__ import annotations

import contextlib
import logging
from typing import Any

from tokenring._native import compiled as _native
from tokenring.contract import ring as R
from tokenring.contract.frame import crc16_arc
from tokenring.contract.ring import ACK_REQUESTED, EPOCH_MASK

log = logging.getLogger("tokenring.node")


class TokenPathHost:
    """The one contract between a token path (:class:`PyTokenPath` or the C type) and the node
    it runs in (:class:`~tokenring.node.node_os.NodeOS`, which derives from both).

    **State.** The fields below are the ring's state as the token path sees it. The node
    initialises them (``NodeOS.__init__``); both paths read and write them under the same
    names (the C type keeps the scalars in C members of these names), and the watchdog, the
    acks and the programs' API read and write them alike under ``_token_lock``.

    **Hooks.** The token path calls the node only through the methods below, and only off its
    fast path (a stale or new epoch, a stranger's token, a command in the token, a visit
    waited for, a failed send); the C path looks them up by these names. Timing sinks
    (``_rounds_add``, ``_handler_add``, ``_send_add``) are plain callables the node supplies.
    """

    # --- set up by the node ------------------------------------------------------------------
    node_id: int
    stats: Any  # NodeStats: counters the path increments
    membership: Any  # tokenring.contract.ring.Membership: the successor
    transport: Any  # tokenring.transport.base.Transport: how frames go out
    system_handler: Any  # system commands in the token (the system layer), or None
    rx_fault: Any  # fault hooks (tokenring.node.faults), None while no fault is active
    tx_fault: Any
    pacer: Any  # emulated hardware timing (tokenring.node.pacing), or None
    _token_lock: Any  # the node's lock around the token's state
    _wake_lock: Any  # released to wake the watchdog
    _defer_lock: Any  # the Python path's: guards _deferred_pending
    _rt: Any  # the runtime (tokenring.runtime) the node was made in
    _now: Any  # its monotonic clock (time.monotonic itself in the real runtime): the Python path's
    _sleep: Any  # its sleep: the Python path's emulated wire time
    _live: Any  # set of live node IDs (membership's)
    _excluded: Any  # set of excluded node IDs
    _senders: dict[int, Any]  # successor ID -> transport sender
    _active: tuple[Any, ...]  # the registered, unlocked channels visited in the token
    _pending_outboxes: list[Any]
    _outboxes: dict[str, Any]
    _rounds_add: Any  # callable(seconds): one round's time
    _handler_add: Any  # callable(seconds): one visit's time in the handler
    _send_add: Any  # callable(seconds): one timed send
    _defer: Any = None  # callable(frame): hand a frame to the node's token thread
    _counters: Any  # the per-visit counters, NodeStats's (Counters in C, else PyCounters)
    # --- the token and its layout (protocol.yaml) ----------------------------------------------
    _work: bytearray  # the working frame: token + CRC
    _work_body: memoryview
    _const_bytes: bytes  # the header's constant markers, from _const_lo
    _token_size: int
    _frame_size: int
    _o_sid: int  # header offsets
    _o_did: int
    _o_counter: int
    _o_issuer: int
    _o_epoch: int
    _o_origin: int
    _const_lo: int
    # --- the ring's state ----------------------------------------------------------------------
    _epoch: int  # the epoch this node is in, and who started it
    _origin: int
    _accepted_crc: int  # the pass last taken (a retry of it is acknowledged, not visited)
    _accepted_sid: int
    #: ... and its bytes: a CRC-16 alone is no identity (two different passes from one sender
    #: share it once in 65536, and the second was dropped as a retry: a lost token, about 20
    #: an hour on the robot's ring, whose data changes at every pass)
    _accepted_frame: bytes
    _last_counter: int  # the round counter last visited in this epoch (-1: none yet)
    _retries: int  # of the pass in flight
    _last_sent_did: int
    _last_sent_crc: int
    _confirmed_did: int  # the successor whose ack last arrived, and when
    _regeneration_streak: int
    _visit_waiters: int  # programs waiting in wait_visit()
    _deferred_pending: int = 0  # frames queued for the token thread
    _last_seen: float  # times on the node's clock (_now)
    _last_visit: float
    _last_sent_time: float
    _confirmed_at: float
    _recovery_until: float
    _ack_interval: float
    _hop: float  # emulated wire time per pass (0: none)
    _paced: float
    _ack_pending: bool
    _has_sent: bool
    _ack_adaptive: bool
    _ack_always: bool
    _closing: bool = False
    _leaving: bool = False
    _departed: bool = False

    # --- hooks ------------------------------------------------------------------------------------
    def _send_ack(self, did: int, crc: int) -> None:
        """Acknowledge the pass ``crc`` that node ``did`` sent here."""
        raise NotImplementedError

    def _answer_stale(self, sid: int, crc: int) -> None:
        """``sid`` passed a token of an older epoch: tell it (the frame was dropped)."""
        raise NotImplementedError

    def _adopt_epoch(self, epoch: int, origin: int, now: float) -> None:
        """A token of a newer epoch arrived: join it (before the visit goes on)."""
        raise NotImplementedError

    def _include(self, node_id: int, tell: bool = False) -> None:
        """A token came from a node this one had excluded: it is back in the ring."""
        raise NotImplementedError

    def _activate_outboxes(self) -> None:
        """Commands queued by programs since the last visit join the visited channels."""
        raise NotImplementedError

    def _drop_outboxes(self, finished: list[Any]) -> None:
        """Commands acknowledged (or given up) in this visit leave the visited channels."""
        raise NotImplementedError

    def _sweep_own_commands(self, work: bytearray) -> None:
        """After a regeneration: clear this node's commands the old token left behind."""
        raise NotImplementedError

    def _notify_visit(self) -> None:
        """Wake programs waiting for a visit (``wait_visit``)."""
        raise NotImplementedError

    def _send_failed(self, did: int, exc: BaseException) -> None:
        """Sending the token to ``did`` raised ``exc``."""
        raise NotImplementedError


class PyTokenPath(TokenPathHost):
    """The token path in Python: the fallback where the C extension is missing, and the
    reference the native path is tested against."""

    system_busy = False  # a system command is queued or in flight here (set by the system layer)

    def _on_frame(self, frame: bytes) -> None:
        """A frame received: visited here, or handed to the token thread when the visit may wait
        (wire time, a pacer, a fault hook), and every frame while one is queued there, to keep
        their order — Zenoh's receiving thread must never wait: it also carries the node's
        acks, events and control queries. A lone node's pass to itself is handed over too:
        Zenoh delivers it inside the sender's own put, so visiting it here would recurse
        once per pass until the stack overflows."""
        if self._defer is not None:
            with self._defer_lock:
                deferred = (
                    self._deferred_pending > 0
                    or self._hop != 0.0
                    or (len(frame) > self._o_sid and frame[self._o_sid] == self.node_id)
                    or self.pacer is not None
                    or self.rx_fault is not None
                    or self.tx_fault is not None
                )
                if deferred:
                    self._deferred_pending += 1
            if deferred:
                self._defer(frame)
                return
        self._visit_frame(frame)

    def _deferred_done(self) -> None:
        """The token thread finished a frame handed to it."""
        with self._defer_lock:
            self._deferred_pending = max(0, self._deferred_pending - 1)

    def _visit_frame(self, frame: bytes) -> None:
        """The token handler: one call per frame."""
        t_in = self._now()
        stats = self.stats
        counters = self._counters  # the hot counters themselves (stats reads them through properties)
        counters.frames_received += 1
        if self.rx_fault is not None and self.rx_fault(frame):
            return
        if self._departed:
            return
        size = self._token_size
        if len(frame) != self._frame_size:
            stats.rejected_length += 1
            return
        # CRC-16/ARC over a frame and its own (little-endian) CRC is zero: no slicing, no view
        if crc16_arc(frame):
            stats.rejected_crc += 1
            return
        crc = frame[size] | (frame[size + 1] << 8)
        if not frame.startswith(self._const_bytes, self._const_lo):
            stats.rejected_marker += 1
            return
        if frame[self._o_did] != self.node_id:
            stats.rejected_did += 1
            return
        sid = frame[self._o_sid]
        if sid not in self._live:
            stats.rejected_sid += 1
            return
        flags = frame[self._o_epoch]
        # byte for byte: two different passes share a CRC-16 once in 65536 (see _accepted_frame)
        if crc == self._accepted_crc and sid == self._accepted_sid and frame == self._accepted_frame:
            stats.duplicate_passes += 1  # a retry of a pass we already took
            if flags & ACK_REQUESTED:
                self._send_ack(sid, crc)
            return
        epoch, origin = flags & EPOCH_MASK, frame[self._o_origin]
        if epoch != self._epoch or origin != self._origin:
            if R.epoch_order(epoch, origin, self._epoch, self._origin) < 0:
                self._answer_stale(sid, crc)
                return
            self._adopt_epoch(epoch, origin, t_in)
        elif self._last_counter >= 0:
            # within one epoch every node gets each round once: an older round, or the same
            # round with other bytes (a retry repeats them all), is a replayed pass or a second
            # token — dropped, so its sender skips us into a new epoch that outlives the other
            back = (self._last_counter - frame[self._o_counter]) & 0xFF
            if 0 < back < 128 or (back == 0 and frame != self._accepted_frame):
                stats.replayed_passes += 1
                return
        self._accepted_crc, self._accepted_sid = crc, sid
        self._accepted_frame = frame if type(frame) is bytes else bytes(frame)
        if sid in self._excluded:
            self._include(sid, True)
        with self._token_lock:
            work = self._work
            work[:] = frame
            self._last_seen = t_in
            if self._leaving:
                self._forward(t_in)
                if flags & ACK_REQUESTED:
                    self._send_ack(sid, crc)
                return
            counter = work[self._o_counter]
            system = self.system_handler
            if system is None:
                system_active = work[self._o_issuer] != 0
            elif work[self._o_issuer] or self.system_busy:
                system_active = system(work)
            else:
                system_active = False
            if not system_active:
                finished = None
                for item in self._active:
                    if item.visit(work) is True:
                        finished = finished or []
                        finished.append(item)
                if finished:
                    self._drop_outboxes(finished)
                if self._pending_outboxes:
                    self._activate_outboxes()
                if t_in < self._recovery_until and self._outboxes:
                    self._sweep_own_commands(work)
            # a round starts where the ring wraps: the node that gets the token from a higher ID
            # counts it (main, the lowest ID, in the robot's ring; a lone node at every pass).
            # This needs no shared view of who is in the ring, so even while views differ
            # (a partition healing) exactly one node per round counts, and no two rounds
            # carry identical bytes that a receiver would take for a retransmission.
            wraps = sid >= self.node_id
            if wraps:
                work[self._o_counter] = (counter + 1) & 0xFF
            self._paced = 0.0
            self._forward(t_in)
            # the handler's time: from the frame's arrival to the put that passes it on (the time
            # the token is held here), without the emulated wire time
            held = self._last_sent_time - t_in - self._paced
            # bookkeeping after the pass: on a loaded machine it overlaps the successor's work
            # instead of delaying the token (bench/RESULTS.md measures the per-hop cost)
            if self._last_visit:
                self._rounds_add(t_in - self._last_visit)
            self._last_visit = t_in
            if self._regeneration_streak:  # the token is back: the loss timer starts afresh
                self._regeneration_streak = 0
                self._wake()
            if (counter - self._last_counter) & 0xFF > 1 and self._last_counter >= 0:
                counters.rounds_missed += ((counter - self._last_counter) & 0xFF) - 1
            self._last_counter = counter
            counters.visits += 1
            if wraps:
                counters.rounds += 1
        if flags & ACK_REQUESTED:  # after the pass: the token must not wait for our ack
            self._send_ack(sid, crc)
        self._handler_add(held)
        if self._visit_waiters:
            self._notify_visit()

    def _forward(self, t_in: float) -> None:
        """Seal and pass the working token to the successor (caller holds the token lock).

        The working buffer is the last frame sent until the next accepted one replaces it, so
        retries and regeneration need no copy.
        """
        work = self._work
        did = self.membership.successor
        work[self._o_sid] = self.node_id
        work[self._o_did] = did
        if did == self.node_id:
            want_ack = arm_now = False
        elif self._ack_adaptive:
            # a new link or a recovering ring: wake the watchdog to arm the ack timer now. A
            # link's periodic confirmation is checked on its next wake instead: if the successor
            # hung, the token is lost and regenerated as after any unasked pass, and at 255 nodes
            # two wakes per confirmation were a third of a node's Python CPU per visit
            arm_now = did != self._confirmed_did or t_in < self._recovery_until
            want_ack = arm_now or t_in - self._confirmed_at > self._ack_interval
        else:
            want_ack = arm_now = self._ack_always
        work[self._o_epoch] = self._epoch | ACK_REQUESTED if want_ack else self._epoch
        work[self._o_origin] = self._origin
        size = self._token_size
        crc = crc16_arc(self._work_body)
        work[size] = crc & 0xFF
        work[size + 1] = crc >> 8
        hop = self._hop if self.pacer is None else self.pacer(t_in)  # --profile: tokenring.node.pacing
        if did == self.node_id:
            hop = max(hop, 0.001)
        if hop:
            now = self._now
            delay = t_in + hop - now()
            if delay > 0:
                slept_from = now()
                self._sleep(delay)  # emulated wire time; a lone node also waits 1 ms per pass
                self._paced += now() - slept_from  # with the sleep's overshoot
        if did != self._last_sent_did or not self._ack_pending:
            self._retries = 0
        elif self._retries:
            # the previous pass to this successor is still unanswered after a retry: a new
            # token must not restart the count, or a hung successor eats token after token
            self._retries += 1
        self._last_sent_did = did
        self._last_sent_crc = crc
        self._has_sent = True
        self._ack_pending = want_ack or (self._ack_pending and self._retries > 0)
        self._last_sent_time = self._now()  # also ends the handler's time (see _on_frame)
        self._transmit(did)
        if arm_now:
            self._wake()

    def _transmit(self, did: int) -> None:
        """Send the working buffer to ``did`` as it is (a pass, a retry, a regeneration)."""
        if self._closing:
            return
        if self.tx_fault is not None and self.tx_fault(did, self._work):
            return
        try:
            sender = self._senders.get(did)
            if sender is None:
                sender = self._senders[did] = self.transport.sender(did)
            counters = self._counters
            if counters.frames_sent & 15:
                sender(self._work)
            else:  # every 16th send is timed
                t0 = self._now()
                sender(self._work)
                self._send_add(self._now() - t0)
            counters.frames_sent += 1
        except Exception as exc:
            self._send_failed(did, exc)

    def _wake(self) -> None:
        """Wake the watchdog (idempotent)."""
        with contextlib.suppress(RuntimeError):  # already awake
            self._wake_lock.release()


#: the counters every visit adds to (NodeStats keeps them in a Counters object: C integers
#: where the token path is in C)
HOT_COUNTERS = ("frames_received", "frames_sent", "visits", "rounds", "rounds_missed")


class PyCounters:
    """The per-visit counters of the Python token path (the C path's ``Counters``)."""

    __slots__ = HOT_COUNTERS

    def __init__(self) -> None:
        for name in HOT_COUNTERS:
            setattr(self, name, 0)


def new_counters() -> Any:
    """Counters for a new node: the C type where the token path is in C."""
    return _native.Counters() if _native is not None else PyCounters()


#: what NodeOS inherits its token path from
TokenPathBase: type = _native.TokenPath if _native is not None else PyTokenPath
#: True when the token path runs in C
NATIVE: bool = _native is not None
