"""Reading a captured wire: retransmissions, the one-token invariant, full rounds, recovery.

With exactly one token every fresh frame is sent by the node that received the previous fresh
frame; two tokens interleave and break that chain. A retransmission (a pass repeated because its
acknowledgement was late) repeats the previous frame to the same receiver bit for bit and is
no new pass. ``chaos``, the recovery benchmark and the tests all judge the ring with this.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from tokenring.contract.frame import crc16_arc
from tokenring.contract.protocol import Protocol, default_protocol
from tokenring.contract.ring import EPOCH_MASK, epoch_order


class CapturedFrames:
    """Frames with their arrival times (``perf_counter`` s), appended by a capture's own thread
    and read by the judge's: a subscriber's (:class:`tokenring.chaos.runner.WireCapture`) or the wire's
    (:class:`tokenring.observe.pcap_tap.WireTap`)."""

    def __init__(self) -> None:
        self.frames: list[tuple[float, bytes]] = []
        self._lock = threading.Lock()

    def _add(self, t: float, frame: bytes) -> None:
        with self._lock:
            self.frames.append((t, frame))

    def snapshot(self) -> list[tuple[float, bytes]]:
        """The frames so far, oldest first."""
        with self._lock:
            return list(self.frames)

    def clear(self) -> None:
        """Forget the frames so far (between trials)."""
        with self._lock:
            self.frames.clear()


@dataclass(frozen=True)
class Pass:
    """One fresh frame on the wire."""

    t: float
    sid: int
    did: int
    epoch: int
    origin: int
    counter: int
    crc: int


def passes(
    frames: Iterable[tuple[float, bytes]], protocol: Protocol | None = None, drop_stale: bool = True
) -> tuple[list[Pass], int]:
    """Fresh passes from raw ``(time, frame)`` captures, and how many frames were skipped.

    Skipped: retransmissions, frames of the wrong length or CRC, and (``drop_stale``) frames of
    an epoch older than the newest already on the wire — what a receiver drops is no token."""
    protocol = protocol or default_protocol()
    h = protocol.header
    size = protocol.token_size
    out: list[Pass] = []
    last_frame: dict[int, bytes] = {}  # per receiver: a retransmission repeats every byte
    newest: tuple[int, int] | None = None
    skipped = 0
    for t, frame in frames:
        if len(frame) != protocol.frame_size:
            skipped += 1
            continue
        crc = frame[size] | (frame[size + 1] << 8)
        if crc16_arc(frame[:size]) != crc:
            skipped += 1
            continue
        did = frame[h.did]
        if last_frame.get(did) == frame:  # not the CRC alone: one pass in 65536 shares it
            skipped += 1
            continue
        last_frame[did] = bytes(frame)
        epoch, origin = frame[h.epoch] & EPOCH_MASK, frame[h.epoch_origin]
        if newest is None or epoch_order(epoch, origin, *newest) > 0:
            newest = (epoch, origin)
        elif drop_stale and epoch_order(epoch, origin, *newest) < 0:
            skipped += 1
            continue
        out.append(Pass(t, frame[h.sid], did, epoch, origin, frame[h.counter], crc))
    return out, skipped


def chain_breaks(seq: Sequence[Pass]) -> list[int]:
    """Indices where a node received a round counter that does not move forward: the same
    round twice or an older one (a second token), within one epoch.

    Judged per receiver: all frames to one node come from its predecessor over one link, so
    their order on the wire is reliable even where frames of different links interleave."""
    last: dict[int, tuple[int, int, int]] = {}  # did -> (epoch, origin, counter)
    breaks = []
    for index, p in enumerate(seq):
        previous = last.get(p.did)
        if previous is not None and previous[:2] == (p.epoch, p.origin):
            step = (p.counter - previous[2]) & 0xFF
            if step == 0 or step >= 128:
                breaks.append(index)
        last[p.did] = (p.epoch, p.origin, p.counter)
    return breaks


def epochs(seq: Sequence[Pass]) -> list[tuple[int, int]]:
    """The distinct (epoch, origin) pairs in order of first appearance."""
    seen: list[tuple[int, int]] = []
    for p in seq:
        key = (p.epoch, p.origin)
        if key not in seen:
            seen.append(key)
    return seen


def single_token(seq: Sequence[Pass]) -> bool:
    """Exactly one token: one epoch, and every node's round counter only moves forward."""
    return len(seq) >= 2 and not chain_breaks(seq) and len({(p.epoch, p.origin) for p in seq}) == 1


def settled(seq: Sequence[Pass], fraction: float = 0.5) -> bool:
    """Exactly one token in the last ``fraction`` of a capture (a transient duplicate earlier,
    e.g. a regeneration a loaded machine provoked, must have been eliminated by then)."""
    tail = seq[int(len(seq) * (1 - fraction)) :]
    return single_token(tail)


def _round_time(seq: Sequence[Pass]) -> float:
    gaps = []
    last: dict[int, float] = {}
    for p in seq:
        if p.did in last:
            gaps.append(p.t - last[p.did])
        last[p.did] = p.t
    gaps.sort()
    return gaps[len(gaps) // 2] if gaps else 0.001


def first_full_round(seq: Sequence[Pass], members: Iterable[int], after: float = 0.0) -> float | None:
    """Time at which the first complete round through exactly ``members`` ends: one round
    counter (in one epoch) that every member received from its predecessor in the member ring
    (ID order), all sent at or after ``after``. Rounds are told apart across the counter's
    wrap-around by time."""
    ring = sorted(set(members))
    if not ring:
        return None
    predecessor = {b: a for a, b in zip([ring[-1], *ring[:-1]], ring, strict=True)}
    horizon = 64 * max(_round_time(seq), 1e-4)
    rounds: dict[tuple[int, int, int], list[tuple[float, dict[int, float]]]] = {}
    best: float | None = None
    for p in seq:
        if p.t < after or p.did not in predecessor or predecessor[p.did] != p.sid:
            continue
        clusters = rounds.setdefault((p.epoch, p.origin, p.counter), [])
        if not clusters or p.t - clusters[-1][0] > horizon:
            clusters.append((p.t, {}))
        got = clusters[-1][1]
        got.setdefault(p.did, p.t)
        if len(got) == len(ring):
            end = max(got.values())
            best = end if best is None else min(best, end)
    return best
