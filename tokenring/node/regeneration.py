"""Which token regenerations had a cause: the ledger behind "spurious regenerations per hour".

A node regenerates the token when it has not seen it for the reconfiguration timeout (its rank's
slot later). On a healthy ring that should never happen: a regeneration is *explained* when

* a fault was active on any node of the ring at that moment, or one started or ended within
  the last :data:`QUIET_S` seconds (or :data:`QUIET_RECONS` reconfiguration times, if longer):
  its own faults it sees in its :class:`~tokenring.node.faults.FaultInjector`, the others' faults
  every node announces on ``ctl/*/faultnote`` when they change (a query to the queryables the
  nodes already have: no declaration, no traffic while nothing changes);
* a node came or went (liveliness) within that time: a crash, a leave, a restart;
* the network stalled: the ring's router (``up --router``: the launcher, through which every
  frame passes) did not run for a while — stopped by SIGSTOP or Ctrl-Z, or starved — and says so
  once it runs again (``ctl/*/faultnote`` with the ``stalled`` span), so the regenerations in that
  span and within :data:`QUIET_S` after it are ``network``, counted again out of ``spurious``.

The ring's first token (main's seed, counted by ``tokens_regenerated`` too) is a ``seed``, not a
regeneration. Every other regeneration is **spurious**: nothing was wrong, the token was only
late (on a loaded machine) and the watchdog gave up on it.

The ledger wraps the node's ``_regenerate`` (called by its watchdog, never on the token path), so
the node OS needs no hook for it. ``tokenring status`` and ``monitor`` turn the nodes' counts
and uptimes into a ring-wide rate per hour with :func:`ring_rates`.
"""

from __future__ import annotations

import collections
import logging
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from tokenring import runtime

if TYPE_CHECKING:
    from tokenring.node.faults import FaultInjector
    from tokenring.node.node_os import NodeOS


log = logging.getLogger("tokenring.regeneration")


#: a fault that started or ended this long ago (at least) still explains a regeneration
QUIET_S = 5.0


#: ... or this many reconfiguration times, if longer (a slow bitrate, a backed-off streak)
QUIET_RECONS = 10.0


CAUSES = ("fault", "membership", "network", "spurious")


RECENT = 16  # the last regenerations kept with their time and cause


def per_hour(count: float, seconds: float) -> float | None:
    """``count`` events in ``seconds`` as a rate per hour; None without any time observed."""
    return count * 3600.0 / seconds if seconds > 0 else None


class RegenerationLedger:
    """Counts one node's regenerations by cause: seed, fault, membership change or spurious."""

    def __init__(
        self,
        os_: NodeOS,
        faults: FaultInjector | None = None,
        clock: Callable[[], float] | None = None,
    ) -> None:
        self._rt = runtime.current()  # the node's: its clock, its wall clock, its locks
        self.os = os_
        self.faults = faults
        self.clock = clock = clock or self._rt.monotonic
        self.started = clock()
        self.seeds = 0
        self.counts = dict.fromkeys(CAUSES, 0)
        #: node ID -> (when its last fault notice arrived, whether it had a fault active)
        self.remote: dict[int, tuple[float, bool]] = {}
        self.recent: collections.deque[dict[str, Any]] = collections.deque(maxlen=RECENT)
        #: the spurious ones' entries (wall-clock ``t``), for a stall told about afterwards
        self._spurious: collections.deque[dict[str, Any]] = collections.deque(maxlen=1024)
        #: spans (wall-clock start, end) in which the network stalled, as the router told them
        self.stalls: collections.deque[tuple[float, float]] = collections.deque(maxlen=16)
        self._lock = self._rt.lock()

    def install(self) -> None:
        """Wrap the node's ``_regenerate`` (its watchdog's call) so every regeneration is counted here."""
        original = self.os._regenerate

        def regenerate(now: float) -> None:
            seed = self._is_seed()
            before = self.os.stats.tokens_regenerated
            state = self._state(now)
            original(now)
            if self.os.stats.tokens_regenerated != before:
                try:
                    self.record(seed, state)
                except Exception:  # the watchdog must survive its bookkeeping
                    log.exception("counting a regeneration failed")

        self.os._regenerate = regenerate  # type: ignore[method-assign]

    def _state(self, now: float) -> dict[str, Any]:
        """What the node saw as it decided to regenerate (read before it does): how long since
        its last visit, how many frames already wait for its token thread (a token in hand, not
        yet visited), its rank and timeout, whether its watchdog woke more than a slot late."""
        os_ = self.os
        try:
            timeouts = os_.timing.current
            last_seen = getattr(os_, "_last_seen", 0.0)
            return {
                "since_seen_ms": round((now - last_seen) * 1e3, 1) if last_seen else None,
                "queued": getattr(os_, "_deferred_pending", None),
                "rank": os_.membership.rank(),
                "recon_ms": round(timeouts.recon * 1e3, 1),
                "stalled": getattr(os_, "_stall_wake", 0.0) == now,
            }
        except Exception:  # diagnostics only
            return {}

    def _is_seed(self) -> bool:
        # node.py's own test for the ring's first token: this node never had a visit nor sent
        return getattr(self.os, "_last_visit", 1.0) == 0.0 and not getattr(self.os, "_has_sent", True)

    def note(self, request: dict[str, Any]) -> dict[str, Any]:
        """Control verb ``faultnote``: node ``id`` says its faults changed (``faults``: those active
        now); or the ring's router says the network stalled (``stalled``: [start, end], wall clock)."""
        stalled = request.get("stalled")
        if isinstance(stalled, (list, tuple)) and len(stalled) == 2:
            return {"ok": True, "recounted": self.network_stalled(float(stalled[0]), float(stalled[1]))}
        node_id = int(request.get("id", 0))
        if node_id and node_id != self.os.node_id:
            with self._lock:
                self.remote[node_id] = (self.clock(), bool(request.get("faults")))
        return {"ok": True}

    def network_stalled(self, start: float, end: float) -> int:
        """The network did not carry anything from ``start`` to ``end`` (wall clock): the
        spurious regenerations in that span and up to :meth:`quiet_s` after it become
        ``network``; returns how many."""
        until = end + self.quiet_s()
        with self._lock:
            self.stalls.append((start, end))
            moved = [e for e in self._spurious if start <= e["t"] <= until]
            for entry in moved:
                entry["cause"] = "network"
                self._spurious.remove(entry)
            self.counts["spurious"] -= len(moved)
            self.counts["network"] += len(moved)
        if moved:
            log.info("%d regeneration(s) were the network's: it stalled for %.1f s", len(moved), end - start)
        return len(moved)

    def quiet_s(self) -> float:
        """How long after a fault or a membership change a regeneration is still explained by it."""
        return max(QUIET_S, QUIET_RECONS * self.os.timing.current.recon)

    def cause(self) -> str:
        """Why a regeneration happening now happened: ``fault``, ``membership`` or ``spurious``."""
        now = self.clock()
        quiet = self.quiet_s()
        faults = self.faults
        if faults is not None and (faults.active or now - faults.changed_at < quiet):
            return "fault"
        live = self.os.membership.live
        with self._lock:
            for node_id, (at, active) in self.remote.items():
                if now - at < quiet or (active and node_id in live):
                    return "fault"
        changed = getattr(self.os, "_live_changed_at", 0.0)  # the node's clock
        if changed and self._rt.monotonic() - changed < quiet:
            return "membership"
        wall = self._rt.time()
        with self._lock:
            if any(start <= wall <= end + quiet for start, end in self.stalls):
                return "network"
        return "spurious"

    def record(self, seed: bool, state: dict[str, Any] | None = None) -> str:
        """Count one regeneration that just happened; returns its cause (``seed`` for the first
        token). ``state``: what the node saw as it decided (kept with the recent ones)."""
        cause = "seed" if seed else self.cause()
        with self._lock:
            if seed:
                self.seeds += 1
            else:
                self.counts[cause] += 1
            entry = {"t": round(self._rt.time(), 3), "cause": cause, **(state or {})}
            self.recent.append(entry)
            if cause == "spurious":
                self._spurious.append(entry)
        if cause == "spurious":
            log.info(
                "spurious regeneration (no fault, no membership change in the last %.1f s): %s",
                self.quiet_s(),
                state,
            )
        return cause

    def report(self) -> dict[str, Any]:
        """The counts for ``stats`` queries: seeds, regenerations by cause, uptime, the recent ones."""
        with self._lock:
            regenerated = sum(self.counts.values())
            return {
                "uptime_s": round(self.clock() - self.started, 3),
                "seeds": self.seeds,
                "regenerated": regenerated,
                **self.counts,
                "quiet_s": round(self.quiet_s(), 3),
                "recent": list(self.recent),
            }
