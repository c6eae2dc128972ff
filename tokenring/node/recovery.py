"""Membership and recovery: acks and ring events, who is live, the watchdog, regeneration.

Everything here runs off the token path, on the transport's message thread (acks, ring events,
liveliness) or the node's watchdog thread (timeouts, retries, regeneration). The watchdog's
decision of *when* to regenerate a lost token is :func:`regeneration_deadline`, a pure function
of what the node knows. :class:`RingRecovery` is mixed into :class:`~tokenring.node.node_os.NodeOS`,
which initialises the state it declares.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from tokenring.contract import ring as R
from tokenring.errors import TokenRingError
from tokenring.node.tokenpath import TokenPathHost

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
#: timer, the token-loss timer) instead of waking for it alone: in a big ring on few cores the
#: watchdogs' own wakes are a measurable share of every hop's CPU
REFRESH_SLACK_S = 1.5
#: the watchdog sleeps at most this many reconfiguration times, so a missed wake costs no more
WATCH_MAX_SLEEP_RECONS = 4.0


def regeneration_deadline(
    timeouts: R.Timeouts,
    *,
    now: float,
    booting: bool,
    starts_ring: bool,
    master_live: bool,
    live: int,
    active: int,
    expected: int | None,
    rank: int,
    started_at: float,
    live_changed_at: float,
    last_seen: float,
    stall_wake: float,
    deferred: bool,
    streak: int,
) -> float:
    """When a node that has not seen the token regenerates it (a time on the node's clock): the
    watchdog's one decision, as a function of what it knows (no threads, no clock, no Zenoh).

    ``booting``: no visit and nothing sent yet; ``starts_ring``: the node that seeds the first
    token (main); ``rank``: its place in the regeneration order; ``deferred``: a frame already
    waits for its token thread; ``streak``: its own regenerations that never came back."""
    # while nodes are still coming up (liveliness keeps changing), the ring is not started:
    # as on ARCNET, where every join reconfigures, a ring that starts circulating while a
    # hundred more interpreters boot on the same cores would only reconfigure again and again
    settled = live_changed_at + SETTLE_RECONS * timeouts.recon
    settled = min(settled, started_at + max(SETTLE_CAP_S, 0.5 * live))
    if booting and expected and live < expected:
        # the launcher is still starting nodes (one that died at boot costs this much)
        settled = started_at + max(EXPECT_CAP_S, 0.5 * expected)
    if booting and starts_ring:
        # main starts the ring: wait briefly for a token that may already circulate
        return max(settled, started_at + max(0.15, 4 * timeouts.hop * active))
    # a watchdog that overslept was starved with the rest of the machine: the token is as
    # late as it was, so even the highest rank gives it one slot after waking
    lost_since = max(last_seen + timeouts.recon, stall_wake + timeouts.slot)
    if deferred:
        # a frame already waits for this node's token thread (taken off the wire, not yet
        # visited): the token is here and late, not lost - look again a slot later
        lost_since = max(lost_since, now + timeouts.slot)
    # a token this node regenerated that never came back: wait longer each time (a slow
    # ring is still forming around it), as Ethernet backs off after collisions
    tries = max(0, streak - 1)  # a second try is normal recovery
    backoff = timeouts.recon * min(2**tries - 1, REGENERATION_BACKOFF_MAX)
    deadline = lost_since + rank * timeouts.slot + backoff
    if booting:
        deadline = max(deadline, settled + rank * timeouts.slot)
        if master_live:
            # main is up and has started (or will start) the token: a node joining a big
            # ring on a busy machine may wait seconds before its predecessor routes it here
            deadline += max(1.0, LATECOMER_RECONS * timeouts.recon)
    return deadline


class RingRecovery(TokenPathHost):
    """A node's ring bookkeeping off the token path (mixed into NodeOS, which sets it up)."""

    name: str
    timing: R.Timing
    membership: R.Membership
    expected_nodes: int | None
    preferred_master: int | None
    msg_fault: Callable[[bytes], bool] | None
    paused: bool
    ring_stopping: bool
    _const_hi: int
    _joined: bool
    _started_at: float
    _live_changed_at: float
    _stall_wake: float
    _stopping: Any
    _ack_grace: dict[int, float]
    _skipped_at: dict[int, float]
    _exclusion_backoff: dict[int, float]
    _leaving_nodes: set[int]

    def _bump_epoch(self, now: float) -> None:
        raise NotImplementedError

    def _forward(self, now: float) -> None:
        raise NotImplementedError

    def _transmit(self, did: int) -> None:
        raise NotImplementedError

    def _wake(self) -> None:
        raise NotImplementedError

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
            now = self._now()
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
            self._adopt_epoch(epoch, origin, self._now())
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
            self._last_seen = max(self._last_seen, self._now())  # a fresh token is on its way
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
        if skipped_at is not None and self._now() - skipped_at < FALSE_EXCLUSION_S:
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
        self._live_changed_at = self._now()
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
            self._repass(self._now())

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
        planned = self._now()  # when this loop meant to run next
        while not self._stopping.is_set():
            if self.paused or self._departed:
                self._wake_lock.acquire(timeout=0.05)
                continue
            now = self._now()
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
                for node_id in self.membership.probes_due(now, self._exclusion_backoff):
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
                    if now >= self._ack_due(timeouts):
                        self._pass_timed_out(now)
                    if (
                        self._ack_pending
                    ):  # still waiting, or waiting again: for the retry or the next successor
                        deadlines.append(self._ack_due(timeouts))
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
            wait = max(0.0, min(min(deadlines) - self._now(), WATCH_MAX_SLEEP_RECONS * timeouts.recon))
            planned = self._now() + wait
            self._wake_lock.acquire(timeout=wait)

    def _ack_due(self, timeouts: R.Timeouts) -> float:
        """When the pass in flight counts as unacknowledged (the successor's grace included)."""
        return self._last_sent_time + timeouts.ack * self._ack_grace.get(self._last_sent_did, 1.0)

    def _regeneration_deadline(self, timeouts: R.Timeouts) -> float:
        return regeneration_deadline(
            timeouts,
            now=self._now(),
            booting=self._last_visit == 0.0 and not self._has_sent,
            starts_ring=self.preferred_master == self.node_id,
            master_live=self.preferred_master in self._live,
            live=len(self.membership.live),
            active=len(self.membership.active),
            expected=self.expected_nodes,
            rank=self.membership.rank(),
            started_at=self._started_at,
            live_changed_at=self._live_changed_at,
            last_seen=self._last_seen,
            stall_wake=self._stall_wake,
            deferred=bool(self._deferred_pending),
            streak=self._regeneration_streak,
        )

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
            if self._last_visit and self._now() < self._last_seen + recon:  # as the deadline sums it
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
