"""Reading a captured wire: retransmissions, the one-token invariant, full rounds, recovery.

With exactly one token every fresh frame is sent by the node that received the previous fresh
frame; two tokens interleave and break that chain. A retransmission (a pass repeated because its
acknowledgement was late) repeats the previous frame to the same receiver bit for bit and is
no new pass. ``chaos``, the recovery benchmark and the tests all judge the ring with this.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from tokenring.frame import crc16_arc
from tokenring.protocol import Protocol, default_protocol
from tokenring.ring import EPOCH_MASK, epoch_order


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
    last_crc: dict[int, int] = {}
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
        if last_crc.get(did) == crc:
            skipped += 1
            continue
        last_crc[did] = crc
        epoch, origin = frame[h.epoch] & EPOCH_MASK, frame[h.epoch_origin]
        if newest is None or epoch_order(epoch, origin, *newest) > 0:
            newest = (epoch, origin)
        elif drop_stale and epoch_order(epoch, origin, *newest) < 0:
            skipped += 1
            continue
        out.append(Pass(t, frame[h.sid], did, epoch, origin, frame[h.counter], crc))
    return out, skipped


def chain_breaks(seq: Sequence[Pass]) -> list[int]:
    """Indices where a pass was not sent by the previous pass's receiver (a second token)."""
    return [i for i in range(1, len(seq)) if seq[i].sid != seq[i - 1].did]


def epochs(seq: Sequence[Pass]) -> list[tuple[int, int]]:
    """The distinct (epoch, origin) pairs in order of first appearance."""
    seen: list[tuple[int, int]] = []
    for p in seq:
        key = (p.epoch, p.origin)
        if key not in seen:
            seen.append(key)
    return seen


def single_token(seq: Sequence[Pass]) -> bool:
    """Exactly one token: an unbroken chain in one epoch (needs at least a few passes)."""
    return len(seq) >= 2 and not chain_breaks(seq) and len({(p.epoch, p.origin) for p in seq}) == 1


def settled(seq: Sequence[Pass], fraction: float = 0.5) -> bool:
    """Exactly one token in the last ``fraction`` of a capture (a transient duplicate earlier,
    e.g. a regeneration a loaded machine provoked, must have been eliminated by then)."""
    tail = seq[int(len(seq) * (1 - fraction)) :]
    return single_token(tail)


def first_full_round(seq: Sequence[Pass], members: Iterable[int], after: float = 0.0) -> float | None:
    """Time at which the first complete round through exactly ``members`` (in ID order, one
    unbroken chain, one epoch) ends, counting only passes sent at or after ``after``."""
    ring = sorted(set(members))
    if not ring:
        return None
    successor = {a: ring[(i + 1) % len(ring)] for i, a in enumerate(ring)}
    run: list[Pass] = []
    for p in seq:
        if p.t < after:
            continue
        ok = (
            p.sid in successor
            and successor[p.sid] == p.did
            and (not run or (p.sid == run[-1].did and (p.epoch, p.origin) == (run[-1].epoch, run[-1].origin)))
        )
        if not ok:
            run = []
            continue
        run.append(p)
        if len(run) >= len(ring):
            return p.t
    return None
