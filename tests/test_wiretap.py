"""The outside tap on direct links (issue 23): where the token passes on TCP links no subscriber
sees, ``tokenring bench --tap`` times the rounds from the wire (tcpdump's kernel time stamps of
the master's incoming frames). The judge here is tcpdump's count and spacing of frames, not the
ring's own bookkeeping: each round brings the master one frame, so the wire must show about one
arrival per round and round times whose median is the ring's own."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


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
    from tokenring.wiretap import WireTap, WireTapError

    tap = WireTap(5, interface="no-such-interface0")
    try:
        tap.start(timeout_s=10.0)
    except WireTapError as exc:
        assert "no-such-interface0" in str(exc)
    else:
        tap.stop()
        raise AssertionError("a capture on a missing interface started")
