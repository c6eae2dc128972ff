"""``tokenring watch``: the web view, a recording and the Foxglove bridge in one process. Its
refusals come before it joins a ring (exit 2, one line, nothing written, nothing left serving);
a live ring with all three: tests/ring/web/test_web.py (``up --web --record --foxglove``)."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import urllib.request

import pytest
from mcap.reader import make_reader

from tests.support.processes import run_tokenring
from tests.support.ringutil import tap, wait_ring, wait_until
from tokenring.transport.session import free_port


def one_line_refusal(out, *needles: str) -> None:
    assert out.returncode == 2, (out.stdout, out.stderr)
    assert "Traceback" not in out.stderr and len(out.stderr.strip().splitlines()) == 1, out.stderr
    for needle in needles:
        assert needle in out.stderr, out.stderr


def test_nothing_to_do_is_refused():
    one_line_refusal(run_tokenring("watch", timeout=30), "--web", "--record", "--foxglove")


def test_an_existing_recording_is_neither_replaced_nor_served_around(tmp_path):
    existing = tmp_path / "run.mcap"
    existing.write_bytes(b"keep me")
    port = free_port()
    out = run_tokenring("watch", "--web", "--web-port", str(port), "--record", str(existing), timeout=30)
    one_line_refusal(out, f"--record {existing}", "--force")
    assert existing.read_bytes() == b"keep me" and list(tmp_path.iterdir()) == [existing]
    with socket.socket() as probe:  # nothing was left serving on the port
        probe.bind(("127.0.0.1", port))


@pytest.mark.slow
def test_a_port_in_use_names_its_option_and_writes_nothing(tmp_path):
    target = tmp_path / "run.mcap"
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        for option in ("--web-port", "--foxglove-port"):
            sink = "--web" if option == "--web-port" else "--foxglove"
            out = run_tokenring(
                "watch", sink, option, str(port), "--record", str(target), "-e", endpoint, timeout=60
            )
            one_line_refusal(out, f"{option} {port}")
            assert not target.exists() and not list(tmp_path.iterdir()), list(tmp_path.iterdir())


@pytest.mark.slow
def test_all_three_share_one_session_on_a_live_ring_and_stop_on_sigterm(procs, ring_name, endpoint, tmp_path):
    """One process: the page's API answers, the bridge accepts, and SIGTERM finalises the file
    with the frames the page counted."""
    launcher = procs.tokenring(
        "up",
        "--ring",
        ring_name,
        "--listen",
        endpoint,
        "--nodes",
        "main,motor",
        "--no-world",
        "--no-programs",
    )
    web_port, fox_port = free_port(), free_port()
    recording = tmp_path / "w.mcap"
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20])
        watcher = procs.tokenring(
            "watch",
            "--ring",
            ring_name,
            "-e",
            endpoint,
            "--json",
            "--record",
            str(recording),
            "--web",
            "--web-port",
            str(web_port),
            "--foxglove",
            "--foxglove-port",
            str(fox_port),
            stderr=subprocess.PIPE,
        )  # fmt: skip (the Foxglove SDK logs its server and clients on stderr)
        assert watcher.stdout is not None
        ready = json.loads(watcher.stdout.readline())
        assert ready == {
            "ring": ring_name,
            "web": f"http://127.0.0.1:{web_port}/",
            "foxglove": f"ws://127.0.0.1:{fox_port}",
            "record": str(recording),
            "metrics": None,
            "pcap": None,
        }

        def frames() -> int:
            with urllib.request.urlopen(f"http://127.0.0.1:{web_port}/api/state", timeout=5) as answer:
                return int(json.loads(answer.read())["topics"].get("/web/token", {}).get("frames", 0))

        seen = wait_until(lambda: frames() > 100 and frames(), 60, "the page to count the token's passes")
        with socket.create_connection(("127.0.0.1", fox_port), timeout=5):
            pass
        assert not recording.exists()  # written as .part until it is whole
        watcher.send_signal(signal.SIGTERM)
        assert watcher.wait(30) == 0
    with open(recording, "rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None and summary.statistics is not None
    counts = {
        c.topic: summary.statistics.channel_message_counts.get(i, 0) for i, c in summary.channels.items()
    }
    assert counts["/ring/frame"] >= seen, (
        counts["/ring/frame"],
        seen,
    )  # one feed: the file has all the page saw
    launcher.send_signal(signal.SIGTERM)
    launcher.wait(30)
