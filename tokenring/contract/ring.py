"""The logical ring's rules: membership and successor, epochs, pacing and timeouts.

Timeouts (all derived, never guessed; see docs/ring.md, "Timing"):

* **hop time** — emulated ARCNET wire time of one pass: a 516-byte long packet at 11 bit times
  per byte plus the 15.6 µs token pass, scaled by ``2.5 Mbit/s / bitrate`` (2.286 ms at the
  default 2.5 Mbit/s, 0 at ``max``).
* **ack timeout** — ARCNET's 74.7 µs response timeout scaled by bitrate, but never below
  4 x the 99th percentile of the measured ack latency nor below 5 ms (Python and the OS
  scheduler cannot promise less on a loaded 2-core machine), and never above 50 ms or a sixth
  of the reconfiguration timeout, whichever is longer (so three tries end by half of it).
* **reconfiguration timeout** — ARCNET's 840 ms scaled by bitrate, but never below 10 x the
  median round time (the median, so that a disturbance does not inflate its own timeout),
  3 hop times per live node (a hop at ``max`` counted as 1 ms, so 255 nodes wait 765 ms),
  nor 3 x the 99th percentile of the recent rounds that ended before the timeout (a starved
  machine stretches the tail, not the median: a token 40 x late is late, not lost),
  nor 50 ms. The highest live ID
  regenerates a lost token after it; every next lower rank waits one more ``slot``.
"""

from __future__ import annotations

import math
import struct
import threading
import time
from bisect import bisect_left
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from itertools import islice
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

ARCNET_BITRATE = 2_500_000
ARCNET_PACKET_BYTES = 516
ARCNET_BITS_PER_BYTE = 11
ARCNET_ITT_S = 15.6e-6
ARCNET_RESPONSE_TIMEOUT_S = 74.7e-6
ARCNET_RECON_TIMEOUT_S = 0.840

ACK_FLOOR_S = 0.005
ACK_CAP_S = 0.050
RECON_FLOOR_S = 0.050
#: what one pass costs at least when the wire is not paced (``--bitrate max``): Python and Zenoh
#: on a loaded machine; keeps a large ring's reconfiguration timeout above its round time
HOP_FLOOR_S = 0.001
ACK_RETRIES = 2
MIN_ROUND_SAMPLES = 16  # rounds measured before the timeouts follow the measurements
#: the reconfiguration timeout stays this many times above the 99th percentile of the recent
#: rounds that came back before it; a round that took longer (a lost token, or a late one that
#: was regenerated) is left out, so a loss can never lengthen its own timeout
ROUND_TAIL_FACTOR = 3.0

# header byte ``epoch``: bits 0-6 the ring epoch (mod 128), bit 7 "acknowledge this pass"
EPOCH_MASK = 0x7F
ACK_REQUESTED = 0x80

# small messages on the ack key: b"A" ack, b"S" stale-token notice, b"P" ping of an excluded
# node (answered with an ack); a pass is named by its CRC
ACK_MESSAGE = struct.Struct("<cBHBB")  # kind, from, frame CRC, epoch, origin
# ring events: kind, node, by, epoch, origin
RING_EVENT = struct.Struct("<cBBBB")
EVENT_EXCLUDED = b"X"
EVENT_REJOIN = b"J"
EVENT_LEAVING = b"L"
EVENT_REGENERATED = b"R"
EVENT_RING_STOPPING = b"Q"  # the launcher stops the whole ring: leave without a handover  # ARCNET's reconfiguration burst: everyone restarts its lost-token timer


#: the slowest and fastest wire to emulate, bit/s: below 10k a pass takes over half a second
#: (ARCNET's slowest rate was 19.5 kbit/s); above 100G pacing is nothing ('max' says so)
MIN_BITRATE, MAX_BITRATE = 10e3, 100e9


def parse_bitrate(text: str | float | int | None) -> float | None:
    """``max`` (or None) means no pacing; otherwise bits per second, e.g. ``2.5M``, ``500k``,
    within :data:`MIN_BITRATE`..:data:`MAX_BITRATE`."""
    if text is None:
        return None
    if isinstance(text, int | float):
        value = float(text) if abs(text) < MAX_BITRATE * 10 else math.inf  # (an int may not fit a float)
    else:
        raw = text.strip().lower().removesuffix("bit/s").removesuffix("bps")
        if raw in ("max", "inf", "unlimited"):
            return None
        scale = 1.0
        if raw.endswith("k"):
            scale, raw = 1e3, raw[:-1]
        elif raw.endswith("m"):
            scale, raw = 1e6, raw[:-1]
        elif raw.endswith("g"):
            scale, raw = 1e9, raw[:-1]
        try:
            value = float(raw) * scale
        except ValueError:
            from tokenring.errors import UsageError

            raise UsageError(f"bitrate {text!r}: expected 'max' or a rate like 2.5M, 500k") from None
    if not (math.isfinite(value) and MIN_BITRATE <= value <= MAX_BITRATE):
        from tokenring.errors import UsageError

        raise UsageError(f"bitrate {text!r}: give 'max' or a rate within 10k..100G bit/s (e.g. 2.5M)")
    return value


def format_bitrate(bitrate: float | None) -> str:
    """``2.5M``, ``500k``, ``max``: the form ``parse_bitrate`` reads back."""
    if bitrate is None:
        return "max"
    for scale, unit in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if bitrate >= scale:
            return f"{bitrate / scale:g}{unit}"
    return f"{bitrate:g}"


def hop_time(bitrate: float | None) -> float:
    """Emulated wire time of one token pass at ``bitrate`` (0 at max)."""
    if bitrate is None:
        return 0.0
    scale = ARCNET_BITRATE / bitrate
    return ARCNET_PACKET_BYTES * ARCNET_BITS_PER_BYTE / bitrate + ARCNET_ITT_S * scale


def epoch_order(a_epoch: int, a_origin: int, b_epoch: int, b_origin: int) -> int:
    """+1 if epoch ``a`` is newer than ``b``, -1 if older, 0 if the same.

    Epochs are 7-bit serial numbers (RFC 1982 style, window 64); equal epochs started by
    different nodes are ordered by the starting node's ID, so two partitions that both
    regenerated a token agree on which one survives. Exactly half the circle apart, where
    serial arithmetic makes each older than the other, the starting node's ID decides too: of
    two different epochs exactly one is newer. Origin 0 is no epoch at all (IDs are 1..255): a
    node that has seen no token yet, older than any epoch a token carried — else a respawned
    node's zero, 64 or more behind the ring's epoch, looks newer to the ring's nodes, and they
    drop to it.
    """
    if not a_origin or not b_origin:
        return (a_origin != 0) - (b_origin != 0)
    diff = (a_epoch - b_epoch) & EPOCH_MASK
    if diff == 0 or diff == (EPOCH_MASK + 1) // 2:
        by_origin = (a_origin > b_origin) - (a_origin < b_origin)
        if by_origin or diff == 0:
            return by_origin
        return 1 if a_epoch > b_epoch else -1
    return 1 if diff < (EPOCH_MASK + 1) // 2 else -1


class RollingStats:
    """The last ``size`` float samples: ``add`` on the token path, percentiles off it.

    ``add`` is the bound ``append`` of a bounded deque, a C function: the token path's
    bookkeeping after each pass runs no Python code for it (at 64 nodes every opcode there runs
    out of caches the other nodes evicted, on the cores the next hop needs)."""

    __slots__ = ("_samples", "add")

    def __init__(self, size: int = 2048) -> None:
        self._samples: deque[float] = deque(maxlen=size)
        #: record one sample (the oldest drops out once ``size`` are held)
        self.add: Callable[[float], None] = self._samples.append

    def __len__(self) -> int:
        return len(self._samples)

    def values(self) -> np.ndarray:
        """Samples oldest first (numpy imported here: a node's runtime needs none of it)."""
        import numpy as np

        return np.array(list(self._samples))

    def as_list(self) -> list[float]:
        """Samples oldest first, as plain floats."""
        return list(self._samples)

    def recent(self, count: int) -> list[float]:
        """The last ``count`` samples (newest first), touching only those: copying a full
        16 384-sample deque on every call was a real cost to the watchdog. The token path may append between
        making the iterator and reading it ("deque mutated during iteration"): then read again."""
        while True:
            try:
                return list(islice(reversed(self._samples), count))
            except RuntimeError:
                continue

    def percentile(self, q: float, default: float = 0.0, last: int = 512) -> float:
        """Percentile of the last ``last`` samples (bounded work, off the token path)."""
        return self.percentiles((q,), default, last)[0]

    def percentiles(self, qs: tuple[float, ...], default: float = 0.0, last: int = 512) -> list[float]:
        """Percentiles of the last ``last`` samples from one sort, interpolated as numpy's
        default. Plain Python: every node's watchdog calls this twice a second, and numpy's
        machinery, cold in a process that mostly sleeps, costs far more a call - in a big ring
        on few cores, a visible share of a CPU that bounds the round time."""
        return percentiles(self.recent(last), qs, default)


def percentiles(samples: list[float], qs: tuple[float, ...], default: float = 0.0) -> list[float]:
    """Percentiles ``qs`` (0..100) of ``samples`` from one sort, linearly interpolated as numpy's
    default; ``default`` for each when there are none. Plain Python: no numpy in a node."""
    return sorted_percentiles(sorted(samples), qs, default)


def sorted_percentiles(values: list[float], qs: tuple[float, ...], default: float = 0.0) -> list[float]:
    """:func:`percentiles` of ``values`` already sorted ascending (no second sort)."""
    if not values:
        return [default for _ in qs]
    top = len(values) - 1
    out = []
    for q in qs:
        position = q / 100 * top
        below = int(position)
        above = min(below + 1, top)
        out.append(values[below] + (values[above] - values[below]) * (position - below))
    return out


@dataclass
class Timeouts:
    """The ring's current timeouts in seconds (see the module docstring for the rules)."""

    hop: float
    ack: float
    recon: float
    slot: float
    ack_interval: float


class Timing:
    """Derives the ring's timeouts from the bitrate and the measured pass and round times."""

    def __init__(self, bitrate: float | None, ack_mode: str = "adaptive") -> None:
        self.bitrate = bitrate
        self.ack_mode = ack_mode
        self.scale = 0.0 if bitrate is None else ARCNET_BITRATE / bitrate
        self.hop = hop_time(bitrate)
        self.rounds = RollingStats(16384)  # seconds between two visits of this node
        self.ack_latency = RollingStats(256)  # seconds from pass to its acknowledgement
        self.handler = RollingStats(4096)  # seconds spent in the handler per visit
        self.send = RollingStats(4096)  # seconds the transport took to send a frame
        self._lock = threading.Lock()
        self.round_median = 0.0
        self.samples_used = 0
        self.current = self._derive(live=2)

    def _derive(self, live: int) -> Timeouts:
        # one sort of the last 512 rounds serves the median, the p99 and the tail below: at 255
        # nodes the watchdog's refresh, cold, was most of a node's Python CPU per visit
        rounds = sorted(self.rounds.recent(512))
        self.round_median, round_p99 = sorted_percentiles(rounds, (50, 99), default=0.0)
        previous = getattr(self, "current", None)
        tail = 0.0
        if previous is not None:
            came_back = bisect_left(rounds, previous.recon)  # rounds[:came_back] came back in time
            if came_back:
                tail = ROUND_TAIL_FACTOR * rounds[min(came_back - 1, int(0.99 * came_back))]
        ack_p99 = self.ack_latency.percentile(99, default=0.0)
        recon = max(
            RECON_FLOOR_S,
            10 * self.round_median,  # the median: a disturbance must not inflate its own timeout
            tail,  # ... but a machine starved for minutes stretches every round's tail
            3 * max(self.hop, HOP_FLOOR_S) * live,
            ARCNET_RECON_TIMEOUT_S * self.scale,
        )  # ring-wide quantities only: every node must derive (nearly) the same value, or the
        # highest-rank-first rule breaks (a node's own ack latency must not enter here)
        if len(self.rounds) < MIN_ROUND_SAMPLES:
            recon = max(recon, 0.2)  # not enough measured yet: be patient at start-up
        # capped: three unanswered passes must skip a hung node well before the
        # reconfiguration timeout would regenerate the token instead (a big ring's longer
        # reconfiguration time buys its busier machine a longer cap)
        ack_cap = max(ACK_CAP_S, recon / 6)
        ack = min(max(ACK_FLOOR_S, 4 * ack_p99, ARCNET_RESPONSE_TIMEOUT_S * self.scale), ack_cap)
        return Timeouts(
            hop=self.hop,
            ack=ack,
            recon=recon,
            slot=recon / 4,
            ack_interval=max(0.050, 20 * round_p99),
        )

    def refresh(self, live: int) -> Timeouts:
        """Recompute from the latest measurements (called by the watchdog, not per visit)."""
        with self._lock:
            self.samples_used = len(self.rounds)
            self.current = self._derive(live)
            return self.current

    def due(self) -> bool:
        """True when the first trustworthy measurements have just arrived."""
        return self.samples_used < MIN_ROUND_SAMPLES <= len(self.rounds)


class Membership:
    """Live IDs (from liveliness) minus excluded ones; the successor is the next higher active ID."""

    def __init__(self, own_id: int, clock: Callable[[], float] = time.monotonic) -> None:
        self.own_id = own_id
        self._clock = clock  # when an exclusion may be retried: the node's clock (a simulation's)
        self.live: set[int] = {own_id}
        self.excluded: dict[int, float] = {}  # node -> time its exclusion may be retried
        self._lock = threading.Lock()
        self.active: tuple[int, ...] = (own_id,)
        self.successor = own_id
        self.changes = 0

    def _recompute(self) -> bool:
        active = tuple(sorted(i for i in self.live if i not in self.excluded or i == self.own_id))
        higher = [i for i in active if i > self.own_id]
        successor = higher[0] if higher else active[0]
        changed = successor != self.successor
        self.active = active
        self.successor = successor

        self.changes += 1
        return changed

    def set_live(self, node_id: int, live: bool) -> bool:
        """Record a liveliness change; returns True if the successor changed."""
        with self._lock:
            if live:
                self.live.add(node_id)
                self.excluded.pop(node_id, None)
            elif node_id != self.own_id:
                self.live.discard(node_id)
                self.excluded.pop(node_id, None)
            return self._recompute()

    def exclude(self, node_id: int, retry_after: float) -> bool:
        with self._lock:
            if node_id == self.own_id:
                return False
            self.excluded[node_id] = self._clock() + retry_after
            return self._recompute()

    def include(self, node_id: int) -> bool:
        with self._lock:
            if self.excluded.pop(node_id, None) is None:
                return False
            return self._recompute()

    def probes_due(self, now: float, backoff: dict[int, float]) -> list[int]:
        """Excluded nodes to ping now (they stay excluded until one answers); the next ping
        of each waits ``backoff[node]`` seconds."""
        with self._lock:
            due = [i for i, t in self.excluded.items() if t <= now and i in self.live]
            for node_id in due:
                self.excluded[node_id] = now + backoff.get(node_id, 1.0)
            return due

    def rank(self) -> int:
        """0 for the highest active ID, 1 for the next lower, ..."""
        active = self.active
        return len(active) - 1 - active.index(self.own_id) if self.own_id in active else len(active)
