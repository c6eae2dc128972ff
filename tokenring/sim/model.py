"""The ring's timing model: what its constants and rules (:mod:`tokenring.contract.ring`) make of
a round and of the recovery from a fault, in ms, for ``n`` nodes at a bitrate. In virtual time the
ring's figures must lie within it (``tokenring bench --sim``, ``tokenring sim --chaos``)."""

from __future__ import annotations

from typing import Any

from tokenring.contract.ring import (
    ACK_CAP_S,
    ACK_FLOOR_S,
    ACK_RETRIES,
    ARCNET_BITRATE,
    ARCNET_RECON_TIMEOUT_S,
    ARCNET_RESPONSE_TIMEOUT_S,
    HOP_FLOOR_S,
    RECON_FLOOR_S,
    hop_time,
)


def model(n: int, bitrate: float) -> dict[str, Any]:
    """What the timing model says for ``n`` nodes at ``bitrate``, in ms: a round is ``n`` hops;
    the reconfiguration timeout is the largest of its floors (``Timing._derive`` with every round
    exactly ``n`` hops, so its tail term, 3 rounds, never wins over 10); the ack timeout the
    ARCNET response timeout scaled, within its floor and cap. Recovery bounds:

    * lost token: from the reconfiguration timeout less one round (the regenerating node last saw
      the token up to a round before the loss) to it plus two (the regenerated token's way to
      the highest ID's successor, then once round);
    * crash: at most one round (the predecessor passes on when the liveliness drops);
    * freeze: the lost-token bounds plus the three unacknowledged passes to the hung node.
    """
    hop = hop_time(bitrate)
    scale = ARCNET_BITRATE / bitrate
    round_s = n * hop
    recon = max(RECON_FLOOR_S, 10 * round_s, 3 * max(hop, HOP_FLOOR_S) * n, ARCNET_RECON_TIMEOUT_S * scale)
    ack = min(max(ACK_FLOOR_S, ARCNET_RESPONSE_TIMEOUT_S * scale), max(ACK_CAP_S, recon / 6))
    skip = (ACK_RETRIES + 1) * ack
    ms = 1e3
    return {
        "round_ms": round_s * ms,
        "recon_ms": recon * ms,
        "ack_ms": ack * ms,
        "lost_token_ms": [(recon - round_s) * ms, (recon + 2 * round_s) * ms],
        "crash_ms": [0.0, (round_s + hop) * ms],
        "freeze_ms": [(recon - round_s) * ms, (recon + skip + 2 * round_s) * ms],
    }
