"""The wire judge: one token vs two, robust to frames of different links arriving out of order."""

from __future__ import annotations

from tokenring.contract.frame import Token
from tokenring.observe.capture import chain_breaks, first_full_round, passes, settled, single_token

RING = [10, 20, 30, 40]


def frame(sid: int, did: int, counter: int, epoch: int = 1, origin: int = 10, salt: int = 0) -> bytes:
    token = Token()
    token.sid, token.did, token.counter = sid, did, counter
    token["epoch"], token["epoch_origin"] = epoch, origin
    token.buffer[400] = salt  # payload differs per pass, as real data channels do
    return token.to_frame()


def one_token(rounds: int, start: int = 0) -> list[bytes]:
    out = []
    for r in range(rounds):
        for i, sid in enumerate(RING):
            did = RING[(i + 1) % len(RING)]
            counter = (start + r + (1 if sid == 10 else 0)) & 0xFF  # main counts when it sends
            out.append(frame(sid, did, counter, salt=r))
    return out


def timed(frames: list[bytes]) -> list[tuple[float, bytes]]:
    return [(i * 1e-4, f) for i, f in enumerate(frames)]


def test_one_token_is_one_token_even_when_links_interleave():
    frames = one_token(40)
    # neighbouring frames of different links swap places, as on a tap at full speed
    for i in range(1, len(frames) - 1, 3):
        frames[i], frames[i + 1] = frames[i + 1], frames[i]
    seq, skipped = passes(timed(frames))
    assert skipped == 0
    assert single_token(seq) and settled(seq)
    assert first_full_round(seq, RING) is not None


def test_a_second_token_is_detected():
    first = one_token(40)
    second = one_token(40, start=17)
    mixed = [f for pair in zip(first, second, strict=True) for f in pair]
    seq, _ = passes(timed(mixed))
    assert chain_breaks(seq)
    assert not single_token(seq)


def test_retransmissions_and_stale_epochs_are_not_tokens():
    frames = one_token(10)
    frames.insert(5, frames[4])  # a retransmitted pass: same bytes to the same receiver
    frames.append(frame(20, 30, 3, epoch=0, origin=10))  # an old epoch, dropped by receivers
    seq, skipped = passes(timed(frames))
    assert skipped == 2
    assert single_token(seq)


def test_full_round_needs_every_member_from_its_predecessor():
    seq, _ = passes(timed(one_token(5)))
    assert first_full_round(seq, RING) is not None
    assert first_full_round(seq, [10, 20, 30, 40, 50]) is None  # 50 never got the token
    assert first_full_round(seq, [10, 30]) is None  # 30 gets it from 20, not from 10


def test_a_different_pass_with_the_same_crc_is_a_pass_not_a_retransmission():
    from tests.support.tokenpath_scenario import crc_twin

    frames = one_token(10)
    # the next pass to the same receiver, other bytes, solved to the same CRC-16
    twin = crc_twin(frames[8], frames[4], Token().protocol.token_size)
    frames[8] = twin
    seq, skipped = passes(timed(frames))
    assert skipped == 0 and len(seq) == len(frames)
    assert single_token(seq)
