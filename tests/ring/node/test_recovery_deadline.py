"""When a node regenerates a lost token: tokenring.node.recovery.regeneration_deadline, the watchdog's
one decision, judged without threads, clocks or Zenoh."""

from __future__ import annotations

import pytest

from tokenring.contract.ring import Timeouts
from tokenring.node.recovery import (
    EXPECT_CAP_S,
    LATECOMER_RECONS,
    REGENERATION_BACKOFF_MAX,
    SETTLE_CAP_S,
    regeneration_deadline,
)

T = Timeouts(hop=0.001, ack=0.01, recon=0.1, slot=0.02, ack_interval=0.5)
RUNNING = dict(
    now=100.0, booting=False, starts_ring=False, master_live=True, live=8, active=8, expected=None,
    rank=0, started_at=0.0, live_changed_at=0.0, last_seen=99.0, stall_wake=0.0, deferred=False, streak=0,
)  # fmt: skip


def deadline(**changes) -> float:
    return regeneration_deadline(T, **(RUNNING | changes))


def test_a_running_ring_regenerates_one_timeout_after_the_last_visit_in_rank_order():
    assert deadline() == pytest.approx(99.0 + T.recon)
    assert deadline(rank=3) == pytest.approx(99.0 + T.recon + 3 * T.slot)


def test_a_watchdog_that_overslept_gives_the_token_a_slot_after_waking():
    assert deadline(stall_wake=99.5) == pytest.approx(99.5 + T.slot)


def test_a_frame_queued_for_the_token_thread_is_a_late_token_not_a_lost_one():
    assert deadline(deferred=True) == pytest.approx(100.0 + T.slot)


@pytest.mark.parametrize(
    ("streak", "recons"), [(0, 0), (1, 0), (2, 1), (3, 3), (4, 7), (10, REGENERATION_BACKOFF_MAX)]
)
def test_fruitless_regenerations_back_off_like_ethernet(streak, recons):
    assert deadline(streak=streak) == pytest.approx(99.0 + T.recon + recons * T.recon)


def test_main_seeds_the_first_token_once_the_ring_settled():
    booting = dict(booting=True, starts_ring=True, last_seen=0.0, started_at=10.0, live_changed_at=12.0)
    assert deadline(**booting) == pytest.approx(12.0 + 2 * T.recon)  # two recon times after the last join
    assert deadline(**booting | {"live_changed_at": 0.0}) == pytest.approx(10.0 + 0.15)


def test_a_booting_ring_waits_for_the_nodes_the_launcher_is_still_starting():
    booting = dict(booting=True, starts_ring=True, started_at=10.0, live=3, expected=8)
    assert deadline(**booting) == pytest.approx(10.0 + EXPECT_CAP_S)
    # the settle wait is capped: liveliness that keeps changing cannot hold the ring forever
    churn = dict(booting=True, starts_ring=True, started_at=10.0, live_changed_at=1e6)
    assert deadline(**churn) == pytest.approx(10.0 + SETTLE_CAP_S)


def test_a_booting_node_leaves_the_first_token_to_a_live_main():
    booting = dict(booting=True, last_seen=10.0, started_at=10.0, live_changed_at=10.0, rank=2)
    without_main = deadline(**booting | {"master_live": False})
    assert without_main == pytest.approx(10.0 + 2 * T.recon + 2 * T.slot)  # settled, then its rank
    assert deadline(**booting) == pytest.approx(without_main + max(1.0, LATECOMER_RECONS * T.recon))
