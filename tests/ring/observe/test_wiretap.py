"""The outside tap on direct links (issue 23): where the token passes on TCP links no subscriber
sees, ``tokenring bench --tap`` times the rounds from the wire (tcpdump's kernel time stamps of
the master's incoming frames). The judge here is tcpdump's count and spacing of frames, not the
ring's own bookkeeping: each round brings the master one frame, so the wire must show about one
arrival per round and round times whose median is the ring's own."""

from __future__ import annotations

import itertools
import json
import subprocess
import sys

import pytest

from tests.support.processes import REPO


@pytest.mark.slow
def test_bench_on_direct_links_times_the_rounds_on_the_wire(tmp_path):
    out = tmp_path / "bench.json"
    result = subprocess.run(
        [
            sys.executable, "-m", "tokenring", "bench", "--nodes", "3", "--topology", "links",
            "--rounds", "300", "--warmup", "50", "--tap", "--json", str(out), "--quiet",
        ],
        capture_output=True, text=True, timeout=240, cwd=REPO,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    report = json.loads(out.read_text())
    tap, ring = report["tap_rtt_ms"], report["rtt_ms"]
    # one frame into the master per round: a capture that saw each packet twice (loopback shows
    # both directions) would halve the median; one that missed frames would double rounds
    assert tap["n"] >= 0.9 * 300, tap
    assert 0.8 < tap["median"] / ring["median"] < 1.25, (tap, ring)
    assert "on the wire" in result.stdout


def test_wiretap_refuses_a_capture_it_cannot_start():
    from tokenring.observe.pcap_tap import WireTap, WireTapError

    tap = WireTap.into(5, interface="no-such-interface0")
    try:
        tap.start(timeout_s=10.0)
    except WireTapError as exc:
        assert "no-such-interface0" in str(exc)
    else:
        tap.stop()
        raise AssertionError("a capture on a missing interface started")


def crc16_arc(data: bytes) -> int:
    """CRC-16/ARC bit by bit (poly 0x8005 reflected, init 0), the test's own: the judge of the
    tap's frame search must not be the CRC it searches with."""
    crc = 0
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return crc


def sealed(token: bytes) -> bytes:
    crc = crc16_arc(token)
    return token + bytes([crc & 0xFF, crc >> 8])


def test_crc_of_the_judge_is_arcs():
    assert crc16_arc(b"123456789") == 0xBB3D  # the catalogue's check value


def test_the_tap_finds_the_frame_inside_zenohs_framing_and_nothing_else():
    import random

    from tokenring.contract.protocol import default_protocol
    from tokenring.observe.pcap_tap import find_frame

    protocol = default_protocol()
    rng = random.Random(5)
    frame = sealed(bytes(rng.randrange(256) for _ in range(protocol.token_size)))
    framing = bytes(rng.randrange(256) for _ in range(23))
    assert find_frame(framing + frame, protocol) == frame  # a put's payload ends the packet
    # something Zenoh batched after the frame (an acknowledgement, 12 bytes)
    assert find_frame(framing + frame + bytes(12), protocol) == frame
    broken = bytearray(frame)
    broken[100] ^= 0x01
    assert find_frame(framing + bytes(broken), protocol) is None  # a frame with a bad CRC is none
    assert find_frame(frame[:-1], protocol) is None  # nor is a packet too short to hold one


@pytest.mark.slow
def test_the_tap_on_direct_links_sees_every_pass_of_a_running_ring():
    """Three nodes on links, the wire tapped round all link ports and the router's: the passes
    must chain (each one sent by the receiver of the one before), and the round counter into
    each node must step by one — a frame the tap missed would break both."""
    import io
    import time

    from tokenring.contract.protocol import default_protocol
    from tokenring.host.launcher import Launcher, NodePlan
    from tokenring.observe.pcap_tap import WireTap
    from tokenring.transport.session import free_port

    header = default_protocol().header
    port = free_port()
    launcher = Launcher(
        # ARCNET's own 2.5 Mbit/s, not max: the frames come at the wire's pace, so a reader the
        # loaded host holds back for seconds still finds them in the kernel's capture ring
        [NodePlan(i, "") for i in (10, 20, 30)], ring=f"tap{port}", bitrate="2.5M", listen=[f"tcp/127.0.0.1:{port}"],
        router=True, links=True, log_level="warning", output=io.StringIO(), residents=False,
    )  # fmt: skip
    launcher.start()
    tap = WireTap.around(launcher.link_ports.values(), port)
    try:
        deadline = time.monotonic() + 120
        tap.start()
        while time.monotonic() < deadline and len(tap.snapshot()) < 1000:
            time.sleep(0.2)  # the ring forms (probes, the first token, links matching)
        tap.clear()
        while time.monotonic() < deadline and len(tap.snapshot()) < 3000:
            time.sleep(0.2)
        frames = tap.stop()
    finally:
        tap.stop()
        launcher.stop()
    assert tap.dropped == 0
    assert len(frames) >= 3000, f"{len(frames)} frames in 120 s"
    # judged from the first complete round on: the capture may begin at any hop
    frames = [f for _, f in frames]
    start = next(i for i, f in enumerate(frames) if f[header.did] == 10)
    frames = frames[start:]
    repeats = 0
    last_counter: dict[int, int] = {}
    for previous, frame in itertools.pairwise(frames):
        if frame == previous:  # a retransmission (its acknowledgement was late) repeats a frame
            repeats += 1
            continue
        assert frame[header.sid] == previous[header.did], "a pass the tap did not see"
    for frame in frames:
        did, counter = frame[header.did], frame[header.counter]
        if did in last_counter and counter != last_counter[did]:
            assert (counter - last_counter[did]) & 0xFF == 1, "a round the tap did not see"
        last_counter[did] = counter
    assert {f[header.did] for f in frames} == {10, 20, 30}
    assert repeats < len(frames) // 10


@pytest.mark.slow
def test_recovery_on_direct_links_is_timed_from_the_wire():
    """bench.recovery --topology links: a crashed node's predecessor passes past it through the
    router, a hung one is skipped; the tap must see the ring whole again after each."""
    from bench.recovery import run

    report = run(1, ["crash", "hang"], "adaptive", quiet=True, topology="links")
    assert report["topology"] == "links"
    for trial in report["trials"]:
        assert trial["recovered_ms"] is not None, trial
        assert trial["whole_again"], trial
