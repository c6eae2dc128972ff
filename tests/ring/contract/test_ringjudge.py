"""The independent judge (tests/support/ringjudge.py) on synthetic frames and ledgers: what one token
looks like on the wire, what a second token looks like, and the command ledger's rules."""

from __future__ import annotations

import json
import random
import time
import uuid
from pathlib import Path

import pytest

from tests.support.ringjudge import (
    EPOCH_MASK,
    FrameTap,
    Header,
    crc16_arc,
    judge_ledgers,
    one_token,
)

H = Header.from_protocol()
RING = [10, 20, 30, 40]


def make_frame(sid: int, did: int, counter: int, epoch: int = 1, origin: int = 80, **extra: int) -> bytes:
    """A valid frame; ``ack`` sets bit 7 of the epoch byte, ``data`` fills the user area's first
    byte (content that differs while the header does not)."""
    token = bytearray(H.token_size)
    token[H.sid], token[H.did], token[H.counter] = sid, did, counter
    for offset, value in H.consts:
        token[offset] = value
    token[H.epoch] = (epoch & EPOCH_MASK) | (0x80 if extra.get("ack") else 0)
    token[H.epoch_origin] = origin
    token[100] = extra.get("data", 0)
    return H.seal(token)


def rounds(ring: list[int], count: int, counter: int = 0, epoch: int = 1, origin: int = 80) -> list[bytes]:
    """One token going ``count`` times round ``ring``, in send order: the lowest ID counts."""
    out = []
    for _ in range(count):
        counter = (counter + 1) & 0xFF  # the lowest ID got it from the highest
        for i, sid in enumerate(ring):
            out.append(make_frame(sid, ring[(i + 1) % len(ring)], counter, epoch, origin))
    return out


def heard(frames: list[bytes], shuffle: int | None = None) -> list[tuple[float, bytes]]:
    """What a tap hears: each sender's frames in order; with ``shuffle`` (a seed), senders'
    frames interleave at random, as over separate links at full pace."""
    if shuffle is not None:
        rng = random.Random(shuffle)
        queues = {}
        for f in frames:
            queues.setdefault(f[H.sid], []).append(f)
        frames = []
        while queues:
            sid = rng.choice(sorted(queues))
            frames.append(queues[sid].pop(0))
            if not queues[sid]:
                del queues[sid]
    return [(i * 1e-4, f) for i, f in enumerate(frames)]


def test_crc_is_crc16_arc_and_the_header_comes_from_protocol_yaml():
    assert crc16_arc(b"123456789") == 0xBB3D
    assert (H.sid, H.did, H.counter, H.epoch, H.epoch_origin) == (0, 1, 4, 10, 11)
    assert H.token_size == 512 and H.frame_size == 514
    assert dict(H.consts) == {2: 0, 3: 4}
    frame = make_frame(10, 20, 7)
    assert len(frame) == 514 and crc16_arc(frame) == 0  # ARC over data + its CRC is zero


def test_a_clean_stream_passes_even_when_senders_interleave_out_of_order():
    frames = rounds(RING, 20)
    for seed in (None, 1, 2, 3):
        verdict = one_token(heard(frames, seed), H, members=RING)
        assert verdict.ok, verdict
        assert verdict.fresh == dict.fromkeys(RING, 20)
        assert verdict.repeats == 0 and verdict.bad == 0


def test_two_interleaved_tokens_fail():
    a = rounds(RING, 10, counter=5)
    b = rounds(RING, 10, counter=100)
    both = [f for pair in zip(a, b, strict=True) for f in pair]
    verdict = one_token(heard(both), H)
    assert not verdict.ok
    assert "a jump: a second token" in verdict.problems[0]
    assert "sender 10" in str(verdict)


def test_two_tokens_with_the_same_counter_but_other_content_fail():
    a = rounds(RING, 5)
    b = [make_frame(f[H.sid], f[H.did], f[H.counter], data=1) for f in a]  # a copy that diverged
    both = [f for pair in zip(a, b, strict=True) for f in pair]
    verdict = one_token(heard(both), H)
    assert not verdict.ok
    assert any("sent again with other content" in p for p in verdict.problems), verdict


def test_a_retried_pass_and_a_duplicated_frame_are_retransmissions():
    frames = rounds(RING, 6)
    retried = make_frame(20, 30, 3, ack=True)  # asked for an ack, got none: sent again, bit for bit
    i = frames.index(make_frame(20, 30, 3))
    frames[i : i + 1] = [retried, retried, retried]
    j = frames.index(make_frame(40, 10, 5))
    frames.insert(j, frames[j])  # the duplicate fault: the token goes out twice
    verdict = one_token(heard(frames, 7), H, members=RING)
    assert verdict.ok, verdict
    assert verdict.repeats == 3 and verdict.fresh[20] == 6


def test_a_stale_copy_that_is_no_retransmission_fails():
    frames = rounds(RING, 6)
    frames.append(make_frame(10, 20, 3))  # an old frame again, after newer ones: not a retry
    assert not one_token(heard(frames), H).ok


def test_the_counter_wraps_from_255_to_0():
    verdict = one_token(heard(rounds(RING, 10, counter=250)), H, members=RING)
    assert verdict.ok, verdict


def test_bad_frames_are_ignored():
    frames = rounds(RING, 6)
    corrupt = bytearray(frames[5])
    corrupt[200] ^= 0x10  # one flipped bit: the CRC fails
    wrong_marker = bytearray(H.token_size)
    wrong_marker[H.sid], wrong_marker[3] = 30, 5
    frames[5:5] = [bytes(corrupt), frames[5][:300], H.seal(wrong_marker)]
    verdict = one_token(heard(frames), H, members=RING)
    assert verdict.ok, verdict
    assert verdict.bad == 3 and verdict.frames == 27


def test_an_epoch_change_resets_the_check_but_going_back_fails():
    before = rounds(RING, 5, counter=40, epoch=3, origin=80)
    after = rounds(RING, 5, counter=17, epoch=4, origin=70)  # regenerated from an older copy
    verdict = one_token(heard(before + after, 5), H, members=RING)
    assert verdict.ok, verdict
    assert verdict.epochs[10] == [(3, 80), (4, 70)]
    back = before + after + rounds(RING, 1, counter=45, epoch=3, origin=80)
    verdict = one_token(heard(back), H)
    assert not verdict.ok and "back to epoch (3, 80)" in verdict.problems[0]


def test_members_must_each_pass_to_their_successor_in_one_epoch():
    skipped = rounds([10, 20, 40], 5)  # 30 hung and skipped: 20 passes to 40
    assert one_token(heard(skipped), H, members=[10, 20, 40]).ok
    missing = one_token(heard(skipped), H, members=RING)
    assert not missing.ok and "member 30 sent 0 fresh frames (fewer than 3)" in missing.problems
    outsider = one_token(heard(rounds(RING, 5)), H, members=[10, 20, 40])
    assert not outsider.ok
    assert any("no member" in p for p in outsider.problems) and any(
        "not to its successor 40" in p for p in outsider.problems
    )
    assert not one_token(heard(rounds(RING, 2)), H, members=RING).ok  # fewer than k = 3 each
    assert one_token(heard(rounds(RING, 2)), H, members=RING, k=2).ok
    # two rings that never merged: each alone is one token, together two epochs
    split = rounds([10, 20], 5, epoch=9, origin=20) + rounds([30, 40], 5, epoch=9, origin=40)
    verdict = one_token(heard(split), H, members=RING)
    assert not verdict.ok and any("end in 2 epochs" in p for p in verdict.problems)


def test_the_tap_keeps_every_frame_under_token_with_its_arrival_time():
    from tokenring.transport.zenoh_config import make_config, open_session

    session = open_session(make_config())
    ring = f"j{uuid.uuid4().hex[:8]}"
    try:
        tap = FrameTap(session, ring)
        first = make_frame(10, 20, 1)
        session.put(f"tokenring/{ring}/token/20", first)
        session.put(f"tokenring/{ring}/ack/20", b"A\x0a")  # not a frame
        deadline = time.monotonic() + 10
        while not tap.snapshot() and time.monotonic() < deadline:
            time.sleep(0.01)
        mark = time.perf_counter()
        session.put(f"tokenring/{ring}/token/30", make_frame(20, 30, 1))
        while len(tap.snapshot()) < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
        frames = tap.snapshot()
        assert [f for _, f in frames] == [first, make_frame(20, 30, 1)]
        assert [f for _, f in tap.snapshot(since=mark)] == [make_frame(20, 30, 1)]
        tap.close()
    finally:
        session.close()


# ---------------------------------------------------------------------------------------------
# ledgers


class Ledger:
    """One probe incarnation's ledger file, written as the probe would."""

    def __init__(self, directory: Path, node: int, pid: int, run: int, t: float) -> None:
        self.path = directory / f"ledger-{node}-{pid}.jsonl"
        self.run = run
        self.n = 0
        self.line(t, ev="start", node=node, run=run, pid=pid)

    def line(self, t: float, **fields) -> None:
        with self.path.open("a") as f:
            f.write(json.dumps({**fields, "t": t}) + "\n")

    def send(self, t: float, to: int, result: str | None = "acked") -> tuple[int, int]:
        self.n += 1
        self.line(t, ev="send", to=to, run=self.run, n=self.n)
        if result is not None:
            self.line(t + 0.01, ev="outcome", to=to, n=self.n, result=result)
        return self.run, self.n

    def take(self, t: float, sender: int, command: tuple[int, int]) -> None:
        self.line(t, ev="take", **{"from": sender}, run=command[0], n=command[1])

    def end(self, t: float) -> None:
        self.line(t, ev="quiesced")
        self.line(t + 0.1, ev="stop")


def test_a_clean_exchange_is_ok(tmp_path):
    a, b = Ledger(tmp_path, 10, 100, 11, 0.0), Ledger(tmp_path, 20, 200, 22, 0.0)
    for i in range(5):
        b.take(1 + i, 10, a.send(1 + i, 20))
        a.take(1.5 + i, 20, b.send(1.5 + i, 10))
    a.end(10)
    b.end(10)
    verdict = judge_ledgers(tmp_path)
    assert verdict.ok, verdict
    assert (verdict.sent, verdict.acked, verdict.taken) == (10, 10, 10)
    assert not (verdict.lost or verdict.pending or verdict.lost_at_receiver_crash)


def test_an_acked_command_nobody_took_is_lost(tmp_path):
    a, b = Ledger(tmp_path, 10, 100, 11, 0.0), Ledger(tmp_path, 20, 200, 22, 0.0)
    b.take(1, 10, a.send(1, 20))
    a.send(2, 20)  # acked, never taken
    b.take(3, 10, a.send(3, 20, result="unacked"))  # taken though unacked: the ack was lost
    a.send(4, 20, result="untransmitted")  # not taken, not acked: fine
    a.end(10)
    b.end(10)
    verdict = judge_ledgers(tmp_path)
    assert not verdict.ok
    assert verdict.lost == [(10, 11, 2)]
    assert verdict.taken_unacked == 1 and verdict.unacked == 1 and verdict.untransmitted == 1


def test_a_command_taken_again_by_the_restarted_receiver_is_duplicated(tmp_path):
    a = Ledger(tmp_path, 10, 100, 11, 0.0)
    b1 = Ledger(tmp_path, 20, 200, 22, 0.0)
    command = a.send(1, 20)
    b1.take(1.1, 10, command)
    b2 = Ledger(tmp_path, 20, 201, 23, 6.0)  # killed and respawned: a new run, no memory
    b2.take(6.5, 10, command)  # a regenerated old token brought it back
    a.end(10)
    b2.end(10)
    verdict = judge_ledgers(tmp_path)
    assert not verdict.ok and verdict.duplicated == [(10, 11, 1)]
    assert not (verdict.lost or verdict.phantom or verdict.misdelivered)


def test_a_take_nobody_sent_is_a_phantom_and_one_taken_elsewhere_misdelivered(tmp_path):
    a, b = Ledger(tmp_path, 10, 100, 11, 0.0), Ledger(tmp_path, 20, 200, 22, 0.0)
    c = Ledger(tmp_path, 30, 300, 33, 0.0)
    b.take(1, 10, (11, 7))
    command = a.send(2, 20)
    b.take(2.1, 10, command)
    c.take(2.2, 10, command)
    for ledger in (a, b, c):
        ledger.end(10)
    verdict = judge_ledgers(tmp_path)
    assert not verdict.ok
    assert verdict.phantom == [(10, 11, 7)]
    assert verdict.misdelivered == [(10, 11, 1)] and verdict.duplicated == [(10, 11, 1)]


def test_an_ack_just_before_the_receiver_was_killed_is_not_a_ring_loss(tmp_path):
    a = Ledger(tmp_path, 10, 100, 11, 0.0)
    b1 = Ledger(tmp_path, 20, 200, 22, 0.0)
    b1.take(1, 10, a.send(1, 20))
    a.send(2, 20)  # acked at 2.01; b1 logs one more line, then is killed
    b1.take(2.5, 30, (33, 1))
    b2 = Ledger(tmp_path, 20, 201, 23, 4.0)
    late = a.send(5, 20)  # acked at 5.01 by b2, which lives on 3 s and never takes it
    b2.line(8.0, ev="quiesced")  # ... and is killed without a stop line
    c = Ledger(tmp_path, 30, 300, 33, 0.0)
    c.line(2.4, ev="send", to=20, run=33, n=1)  # killed before its outcome: pending
    a.end(10)
    verdict = judge_ledgers(tmp_path)
    assert verdict.lost_at_receiver_crash == [(10, 11, 2)]
    assert verdict.lost == [(10, *late)]  # its receiver lived on for seconds: a ring loss
    assert verdict.pending == [(30, 33, 1)] and not verdict.unresolved
    assert not verdict.ok
    assert sum(i.killed for i in verdict.incarnations) == 3


def test_a_send_without_outcome_from_a_program_that_stopped_is_unresolved(tmp_path):
    a, b = Ledger(tmp_path, 10, 100, 11, 0.0), Ledger(tmp_path, 20, 200, 22, 0.0)
    a.send(1, 20, result=None)
    a.end(5)
    b.end(5)
    verdict = judge_ledgers(tmp_path)
    assert not verdict.ok and verdict.unresolved == [(10, 11, 1)] and not verdict.pending


def test_a_line_torn_by_a_kill_and_a_reused_pid_are_read(tmp_path):
    a = Ledger(tmp_path, 10, 100, 11, 0.0)
    b = Ledger(tmp_path, 20, 200, 22, 0.0)
    b.take(1.1, 10, a.send(1, 20))
    with b.path.open("a") as f:
        f.write('{"ev": "take", "from": 10, "ru')  # killed mid-write
    again = Ledger(tmp_path, 20, 200, 24, 3.0)  # the same PID again: its start line is glued on
    again.take(3.5, 10, a.send(3, 20))
    a.end(10)
    again.end(10)
    verdict = judge_ledgers(tmp_path)
    assert verdict.ok, verdict
    assert verdict.torn == 1 and len(verdict.incarnations) == 3
    assert [i.run for i in verdict.incarnations if i.node == 20] == [22, 24]


@pytest.mark.parametrize("name", ["notes.txt", "ledger-10-1.json"])
def test_only_ledger_files_are_read(tmp_path, name):
    (tmp_path / name).write_text("not json\n")
    verdict = judge_ledgers(tmp_path)
    assert verdict.ok and verdict.torn == 0 and not verdict.incarnations
