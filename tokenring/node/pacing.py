"""Timing profiles: the seed robot's hardware timing on top of the emulated wire (``--profile``).

``--bitrate`` alone emulates only ARCNET's wire time. The seed's 30-40 ms round trip with seven
computers (seed 001, §3.4.3 item 10) also holds what its 8051s did per visit and the sonar's
interrupt lock. The ``arcnet`` profile adds, per pass, on the node that holds the token:

* **interrupt and header work** — 500 machine cycles of the 8051 (16 MHz, 12 clocks per cycle:
  0.75 µs each), i.e. 375 µs: interrupt entry with the register save, the COM20020's address
  pointer set and the header (SID, DID, counter, system byte) read through its data register,
  the walk over the channel table, the DID written and the transmit started;
* **copying the unlocked channels** — 16 machine cycles (12 µs) per byte of every unlocked data
  channel this node gets or stores (a C51 loop reading the controller's auto-incrementing data
  register with MOVX and writing the user structure in XRAM, switching DPTR each byte); an
  inbox or outbox costs its 4 header bytes per visit (state, sender, sequence, code);
* **the sonar's interrupt lock** — the sonar measures one sensor every ~15 ms and samples it for
  510 x 20 µs = 10.2 ms with the ARCNET interrupt disabled (seed §4.3.2): a token arriving in
  that window waits until it ends. The sonar's cycle is not synchronised with the token, so the
  phase at which the token finds it is drawn at random per visit (on average the token waits
  10.2/15 x 10.2/2 = 3.5 ms there). A strictly periodic 15 ms schedule would instead phase-lock
  with a round near a multiple of 15 ms and make the token wait almost the whole lock every
  round; the real sonar's evaluation time varies with the echo, which breaks such locking.

All three scale with ``2.5 Mbit/s / bitrate`` like the wire time, so ``up --speed K`` (which
speeds the wire up K times) keeps the proportions. The delay is applied where ``--bitrate``
paces, in :meth:`tokenring.node.node_os.NodeOS._forward`: the token leaves no earlier than its arrival
plus the profile's hop time. Without ``--profile`` the node OS does not call into this module.
"""

from __future__ import annotations

import random
from dataclasses import dataclass, field
from typing import Any

from tokenring.contract.ring import ARCNET_BITRATE, hop_time
from tokenring.errors import UsageError
from tokenring.node.channels import DataRegistration

MACHINE_CYCLE_S = 12 / 16e6  # an 8051 at 16 MHz
COMMAND_HEADER_BYTES = 4


@dataclass(frozen=True)
class TimingProfile:
    """Per-visit processing and interrupt locks of one hardware generation."""

    name: str
    description: str
    visit_s: float  # fixed work per visit
    byte_s: float  # per byte of an unlocked channel copied
    locks: dict[str, tuple[float, float]] = field(default_factory=dict)  # node -> (period, locked)
    reference_ms: tuple[float, float] | None = None  # what the real hardware measured
    reference_nodes: int = 0


PROFILES: dict[str, TimingProfile] = {
    "arcnet": TimingProfile(
        name="arcnet",
        description="the Hamburg robot: ARCNET 2.5 Mbit/s, 8051s at 16 MHz, sonar sampling with the "
        "network interrupt locked",
        visit_s=500 * MACHINE_CYCLE_S,
        byte_s=16 * MACHINE_CYCLE_S,
        locks={"sonar": (0.015, 510 * 20e-6)},
        reference_ms=(30.0, 40.0),
        reference_nodes=7,
    )
}


def get_profile(name: str) -> TimingProfile:
    """The profile called ``name``; an unknown name is a usage error listing the known ones."""
    try:
        return PROFILES[name]
    except KeyError:
        raise UsageError(f"--profile {name!r}: unknown (known: {', '.join(PROFILES)})") from None


class Pacer:
    """One node's hop time under a profile: ``pacer(t_in)`` -> seconds the pass may take.

    Installed as ``NodeOS.pacer``; called once per pass on the token path, so it reads the
    node's active registrations directly (a tuple the handler already walks).
    """

    def __init__(self, profile: TimingProfile, node: Any, bitrate: float | None, start: float) -> None:
        if bitrate is None:
            raise UsageError(
                f"--profile {profile.name} emulates hardware timing and needs a bitrate, not max"
            )
        self.profile = profile
        self.node = node
        self.scale = ARCNET_BITRATE / bitrate
        self.wire_s = hop_time(bitrate)
        self.visit_s = profile.visit_s * self.scale
        self.byte_s = profile.byte_s * self.scale
        lock = profile.locks.get(node.name)
        self.lock = None if lock is None else (lock[0] * self.scale, lock[1] * self.scale)
        self._phase = random.Random(int(start * 1e6) ^ node.node_id).random
        self.last_copy_bytes = 0
        self.held_s = 0.0  # total time the token waited for a locked interrupt

    def copy_bytes(self) -> int:
        total = 0
        for item in self.node._active:
            size = item.end - item.start
            total += size if isinstance(item, DataRegistration) else min(size, COMMAND_HEADER_BYTES)
        return total

    def __call__(self, t_in: float) -> float:
        held = 0.0
        if self.lock is not None:
            period, locked = self.lock
            phase = self._phase() * period
            if phase < locked:
                held = locked - phase
                self.held_s += held
        copied = self.copy_bytes()
        self.last_copy_bytes = copied
        return held + self.wire_s + self.visit_s + copied * self.byte_s


def install(node: Any, name: str | None, bitrate: float | None, start: float) -> Pacer | None:
    """Give ``node`` (a NodeOS) the pacer of profile ``name``; None and no hook without one."""
    if not name:
        return None
    pacer = Pacer(get_profile(name), node, bitrate, start)
    node.pacer = pacer
    return pacer
