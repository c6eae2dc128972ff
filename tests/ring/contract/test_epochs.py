"""The epoch order every node, the C token path and the judges share (tokenring.contract.ring).

Found by the seed campaign in virtual time (seed 2219): after some sixty regenerations a node
that had seen no token yet (epoch 0, origin 0) told a node of the ring its epoch, which took the
"0" for newer and dropped out; and two epochs exactly half the 7-bit circle apart were each
older than the other, so neither token was taken. The ring stalled for seconds."""

from __future__ import annotations

import itertools

from tests.support.memring import MemoryRing, in_virtual_time, wait_for
from tests.support.ringjudge import Header, one_token
from tokenring import runtime
from tokenring.contract.ring import EPOCH_MASK, epoch_order

ORIGINS = (0, 1, 10, 80, 255)


def test_of_two_different_epochs_exactly_one_is_newer():
    for a, b in itertools.product(range(EPOCH_MASK + 1), repeat=2):
        for oa, ob in itertools.product(ORIGINS, repeat=2):
            order = epoch_order(a, oa, b, ob)
            assert order == -epoch_order(b, ob, a, oa), (a, oa, b, ob)
            assert (order == 0) == ((a, oa) == (b, ob) or (oa == ob == 0)), (a, oa, b, ob)


def test_no_epoch_yet_is_older_than_every_epoch_a_token_carried():
    # origin 0: the node has seen no token and made none (IDs are 1..255)
    for epoch in range(EPOCH_MASK + 1):
        assert epoch_order(epoch, 70, 0, 0) == 1
        assert epoch_order(0, 0, epoch, 70) == -1


def test_within_the_window_the_later_epoch_is_newer():
    assert epoch_order(5, 10, 4, 80) == 1
    assert epoch_order(0, 10, 127, 80) == 1  # across the wrap
    assert epoch_order(10, 10, 70, 80) == -1  # 60 behind: older
    assert epoch_order(3, 10, 3, 80) == -1  # the same epoch: the higher origin wins


@in_virtual_time(seed=3)
def test_a_node_respawned_after_sixty_five_regenerations_joins_the_ring():
    ring = MemoryRing([10, 20, 30, 40], bitrate=2.5e6, ack_mode="never")
    try:
        ring.wait_rounds(20, timeout=30)
        for lost in range(1, 66):  # every lost token is regenerated in a new epoch
            ring.hub.drop_frames(1)
            wait_for(lambda n=lost: ring.regenerated() >= n + 1, 5, f"regeneration {lost}")
            ring.wait_rounds(5, timeout=5)  # going round again: the next loss is a new one
        assert all(node._epoch >= 64 for node in ring.nodes.values())
        ring.hub.crash(30)
        ring.nodes.pop(30).close()
        regenerated = ring.regenerated()
        fresh = ring.add(30)  # the launcher's respawn: epoch 0, no origin
        # as at any epoch: taken in within rounds, no node dropping to the fresh node's zero
        wait_for(lambda: fresh.stats.visits >= 20, 0.5, "the respawned node taking the token")
        assert ring.regenerated() == regenerated
        ring.hub.wire.clear()
        ring.hub.tapping = True
        runtime.current().sleep(0.3)
        frames = [(float(i), frame) for i, (_, _, frame) in enumerate(ring.hub.wire)]
        verdict = one_token(frames[len(frames) // 2 :], Header.from_protocol(), [10, 20, 30, 40], k=3)
        assert verdict.ok, verdict
    finally:
        ring.close()
