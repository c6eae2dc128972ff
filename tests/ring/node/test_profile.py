"""``--profile arcnet``: the seed's hardware timing on top of the wire (tokenring/node/pacing.py)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tests.support.memring import MemoryRing
from tests.support.processes import run_tokenring
from tokenring.contract.protocol import default_protocol
from tokenring.contract.ring import hop_time
from tokenring.errors import UsageError
from tokenring.node.channels import ChannelBuffer, DataRegistration
from tokenring.node.pacing import COMMAND_HEADER_BYTES, MACHINE_CYCLE_S, PROFILES, Pacer, get_profile, install

ARCNET = PROFILES["arcnet"]


def fake_node(name: str, registrations: tuple = ()) -> SimpleNamespace:
    return SimpleNamespace(name=name, node_id=30, _active=registrations)


def test_the_8051_cost_is_wire_plus_visit_plus_bytes_copied():
    protocol = default_protocol()
    channel = protocol.channel("sonar.data")
    reg = DataRegistration(channel, "get", ChannelBuffer(channel), "program")
    inbox = SimpleNamespace(start=0, end=20)  # anything else counts its command header only
    pacer = Pacer(ARCNET, fake_node("motor", (reg, inbox)), 2.5e6, 0.0)
    copied = channel.size + COMMAND_HEADER_BYTES
    assert pacer.copy_bytes() == copied
    expected = hop_time(2.5e6) + 500 * MACHINE_CYCLE_S + copied * 16 * MACHINE_CYCLE_S
    assert pacer(123.0) == pytest.approx(expected)
    assert 2.9e-3 < expected < 3.2e-3  # 2.29 ms wire + 0.375 ms + 36 x 12 us


def test_the_sonar_holds_the_token_while_its_interrupt_is_locked():
    pacer = Pacer(ARCNET, fake_node("sonar"), 2.5e6, 1.0)
    base = hop_time(2.5e6) + ARCNET.visit_s
    holds = np.array([pacer(0.0) - base for _ in range(20000)])
    period, locked = ARCNET.locks["sonar"]
    assert holds.min() >= 0 and holds.max() <= locked + 1e-12
    assert np.mean(holds == 0) == pytest.approx(1 - locked / period, abs=0.02)
    assert holds.mean() == pytest.approx(locked / period * locked / 2, rel=0.05)  # 3.5 ms
    assert pacer.held_s == pytest.approx(holds.sum())


def test_profile_times_scale_with_the_bitrate_like_the_wire():
    slow, fast = Pacer(ARCNET, fake_node("main"), 2.5e6, 0), Pacer(ARCNET, fake_node("main"), 25e6, 0)
    assert fast(0.0) == pytest.approx(slow(0.0) / 10)


def test_bad_profile_requests_are_usage_errors():
    with pytest.raises(UsageError, match="unknown"):
        get_profile("pdp11")
    with pytest.raises(UsageError, match="needs a bitrate"):
        Pacer(ARCNET, fake_node("main"), None, 0.0)
    assert install(fake_node("main"), None, 2.5e6, 0.0) is None
    result = run_tokenring("bench", "--profile", "arcnet", "--bitrate", "max", timeout=30)
    assert result.returncode == 2 and "not max" in result.stderr and "Traceback" not in result.stderr


def test_a_ring_with_the_profile_takes_what_the_model_says():
    """Three nodes in memory at 25 Mbit/s (everything 10x faster than the seed's hardware):
    every pass takes at least wire + 8051 work, the sonar adds its lock on average."""
    ring = MemoryRing(ids=[10, 20, 30], bitrate=25e6)
    try:
        for node in ring.nodes.values():
            install(node, "arcnet", 25e6, 0.0)
        ring.wait_rounds(30)
        main = ring.by_name("main")
        before = len(main.round_times())
        ring.wait_rounds(150, timeout=10.0)
        rounds = np.array(main.round_times()[before:])
        floor = 3 * (hop_time(25e6) + ARCNET.visit_s / 10)
        assert rounds.min() >= floor * 0.98
        sonar_mean = ARCNET.locks["sonar"][1] ** 2 / ARCNET.locks["sonar"][0] / 2 / 10
        assert np.mean(rounds) > floor + 0.5 * sonar_mean  # the sonar's lock is felt
        assert ring.by_name("sonar").pacer.held_s > 0
        assert ring.by_name("main").pacer.held_s == 0
    finally:
        ring.close()
