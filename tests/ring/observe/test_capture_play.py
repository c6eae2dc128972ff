"""``sniff --write`` against a real ring, and ``play``'s ``--start``, ``--topics``, ``--ring``
and ``--loop`` on that capture.

One capture per module: a three-node ring, ``sniff --json --write F --duration S``. The judges
share no code with what they judge: the file is read with the ``mcap`` package's reader, frames are
checked with protocol.yaml read as plain YAML and a bitwise CRC-16/ARC of the test's own, and
what ``play`` puts on the wire is what a plain Zenoh subscriber (``tokenring/**``) on the other
side receives, compared with the frames the ``mcap`` reader lists.
"""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import time
import uuid
from collections.abc import Iterator
from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path
from typing import Any

import pytest
import yaml
from mcap.reader import make_reader

from tests.support.processes import Processes, run_tokenring
from tests.support.ringjudge import crc16_arc  # the judge's own CRC, not tokenring's
from tests.support.ringutil import launcher_pids, tap, wait_ring, wait_until
from tokenring.contract.protocol import default_protocol_path
from tokenring.transport.session import free_port

PROTOCOL_TEXT = Path(default_protocol_path()).read_text()
PROTOCOL_YAML = yaml.safe_load(PROTOCOL_TEXT)
TOKEN_SIZE = PROTOCOL_YAML["token"]["size"]
HEADER = {name: spec["offset"] for name, spec in PROTOCOL_YAML["token"]["header"].items()}
NODES = {"main": 10, "motor": 20, "sonar": 30}
CAPTURE_S = 4.0  # seconds of a three-node ring (some hundreds of frames a second)


@dataclass
class Capture:
    ring: str
    path: Path
    live: list[dict[str, Any]]  # what sniff --json printed while it wrote the file
    stderr: str


@dataclass
class Frame:
    time_ns: int
    key: str
    payload: bytes


def without_time(line: str) -> dict[str, Any]:
    record = json.loads(line)
    record.pop("t")
    return record


def wait_port(port: int, timeout: float) -> None:
    def accepting() -> bool:
        with socket.socket() as probe:
            probe.settimeout(1.0)
            return probe.connect_ex(("127.0.0.1", port)) == 0

    wait_until(accepting, timeout, f"a listener on port {port}", interval=0.1)


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Capture]:
    """A three-node ring captured by ``sniff --json --write F --force --duration S`` over an old F."""
    folder = tmp_path_factory.mktemp("capture")
    ring = f"t{uuid.uuid4().hex[:10]}"
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    path = folder / "frames.mcap"
    path.write_text("an older capture, replaced with --force\n")
    tracker = Processes()
    try:
        launcher = tracker.tokenring(
            "up", "--ring", ring, "--listen", endpoint, "--nodes", ",".join(NODES), "--no-world",
            "--no-programs", "--duration", "150",
        )  # fmt: skip
        with tap(endpoint) as session:
            wait_ring(session, ring, list(NODES.values()), timeout=120)
            tracker.watch(launcher_pids(session, ring))
        sniff = tracker.tokenring(
            "sniff", "--ring", ring, "-e", endpoint, "--json", "--write", str(path), "--force",
            "--duration", str(CAPTURE_S), stderr=subprocess.PIPE,
        )  # fmt: skip
        out, err = sniff.communicate(timeout=120)
        assert sniff.returncode == 0, err
        launcher.terminate()
        launcher.communicate(timeout=60)
        assert launcher.returncode == 0
        yield Capture(ring, path, [without_time(line) for line in out.splitlines()], err)
    finally:
        leaked = tracker.cleanup()
    assert not leaked, leaked


def recorded_frames(path: Path) -> list[Frame]:
    """The raw frames of the file, in log-time order, as the mcap package reads them."""
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None
        raw = [c.topic for c in summary.channels.values() if c.message_encoding == "tokenring.zenoh"]
        return [
            Frame(m.log_time, channel.topic, bytes(m.data))
            for _, channel, m in reader.iter_messages(topics=raw)
        ]


def recording_start(path: Path) -> int:
    with open(path, "rb") as stream:
        summary = make_reader(stream).get_summary()
        assert summary is not None and summary.statistics is not None
        return summary.statistics.message_start_time


# --------------------------------------------------------------------------------------------
# sniff --write


@pytest.mark.slow
@pytest.mark.timeout(300)  # the module's ring and capture start in the first test
def test_sniff_write_holds_exactly_the_frames_sniff_printed(capture: Capture) -> None:
    live = capture.live
    assert len(live) > 100 * CAPTURE_S, len(live)
    assert f"{capture.path}:" in capture.stderr and "captured" in capture.stderr

    # the mcap package's reader: the raw frames, whole and sealed, on the ring's token keys
    frames = recorded_frames(capture.path)
    assert len(frames) == len(live)
    for frame, printed in zip(frames, live, strict=True):
        ring, kind, did = frame.key.split("/")[1:]
        assert (ring, kind) == (capture.ring, "token") and int(did) in NODES.values(), frame.key
        assert len(frame.payload) == TOKEN_SIZE + 2
        crc = crc16_arc(frame.payload[:TOKEN_SIZE])
        assert frame.payload[TOKEN_SIZE:] == bytes([crc & 0xFF, crc >> 8]), frame.key
        assert frame.payload[HEADER["did"]] == int(did)
        # the frame sniff printed at this point is the frame the file holds here
        header = {name: frame.payload[offset] for name, offset in HEADER.items()}
        assert printed["key_did"] == int(did) and printed["crc"] == crc and printed["crc_ok"]
        assert {name: printed["header"][name] for name in HEADER} == header
    # the round counter advances (main adds one per round): from one frame to a node to the
    # next to the same node (one sender, one link: in order) it never steps back (serial
    # arithmetic), 0 for a pass sent again (a late acknowledgement), 1 a round later, more only
    # past a frame lost on the way to sniff; a new epoch (a regenerated token) aside. Between
    # frames to different nodes it may step back: they come over different links.
    steps = []
    for did in NODES.values():
        to_node = [f.payload for f in frames if f.key.endswith(f"/token/{did}")]
        steps += [
            (b[HEADER["counter"]] - a[HEADER["counter"]]) % 256
            for a, b in pairwise(to_node)
            if a[HEADER["epoch"]] == b[HEADER["epoch"]]
        ]
    assert all(step < 128 for step in steps) and steps.count(1) >= 50, sorted(set(steps))
    assert {int(f.key.rsplit("/", 1)[1]) for f in frames} == set(NODES.values())

    # the decoded topics and what makes the file stand alone
    with open(capture.path, "rb") as stream:
        reader = make_reader(stream)
        headers = [json.loads(m.data) for _, _, m in reader.iter_messages(topics=["/ring/frame"])]
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        attachments = {a.name: bytes(a.data) for a in reader.iter_attachments()}
    assert [(h["did"], h["counter"]) for h in headers] == [
        (f.payload[HEADER["did"]], f.payload[HEADER["counter"]]) for f in frames
    ]
    assert metadata["tokenring"]["ring"] == capture.ring
    assert attachments["protocol.yaml"].decode() == PROTOCOL_TEXT

    # sniff --read decodes the file into exactly what sniff printed live
    offline = run_tokenring("sniff", "--read", str(capture.path), "--json", timeout=120)
    assert offline.returncode == 0, offline.stderr
    assert [without_time(line) for line in offline.stdout.splitlines()] == live

    # the file exists now: without --force it is kept, refused in one line, exit 2
    before = capture.path.read_bytes()
    again = run_tokenring("sniff", "--write", str(capture.path), "--ring", capture.ring, "-n", "1")
    assert again.returncode == 2, (again.returncode, again.stderr)
    lines = again.stderr.strip().splitlines()
    assert len(lines) == 1 and "--write" in lines[0] and "exists" in lines[0], again.stderr
    assert "Traceback" not in again.stderr and capture.path.read_bytes() == before


@pytest.mark.slow
def test_a_capture_that_got_no_frame_leaves_no_file(tmp_path: Path) -> None:
    """A refused endpoint, or a ring that sends nothing: one error line, and neither FILE nor
    FILE.part (a retry without --force must not be refused over an empty capture); an older
    FILE given with --force is left as it was."""
    target = tmp_path / "none.mcap"
    bad = run_tokenring("sniff", "--write", str(target), "-e", "bogus:1")
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1, bad.stderr
    assert "bogus:1" in bad.stderr and list(tmp_path.iterdir()) == []
    nobody = f"tcp/127.0.0.1:{free_port()}"
    silent = run_tokenring("sniff", "--write", str(target), "--ring", "nobody", "-e", nobody, "--wait", "1")
    lines = silent.stderr.strip().splitlines()
    assert silent.returncode == 1 and len(lines) == 1 and "no frame" in lines[0], silent.stderr
    assert "Traceback" not in silent.stderr and list(tmp_path.iterdir()) == []
    older = tmp_path / "older.mcap"
    older.write_text("an older capture\n")
    forced = run_tokenring(
        "sniff", "--write", str(older), "--force", "--ring", "nobody", "-e", nobody, "--wait", "1"
    )
    assert forced.returncode == 1 and older.read_text() == "an older capture\n", forced.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["older.mcap"]


# --------------------------------------------------------------------------------------------
# play's options, judged by a plain subscriber on the other side


def play_watched(
    path: Path, *options: str, ring: str, expect: int, interrupt: bool = False
) -> tuple[list[tuple[str, bytes]], dict[str, Any], int]:
    """Play ``path`` into a fresh endpoint with ``options``; a subscriber to ``tokenring/**``
    there collects (key, payload) of the recorded ``ring`` and of ``--ring {ring}x``, should play put
    them anywhere else, until ``expect`` samples came (then play is interrupted with SIGINT if
    ``interrupt``, else it runs to its end). Returns the samples, play's JSON summary and its
    exit code."""
    rings = (f"tokenring/{ring}/", f"tokenring/{ring}x/")
    endpoint_port = free_port()
    tracker = Processes()
    got: list[tuple[str, bytes]] = []
    try:
        player = tracker.tokenring(
            "play", str(path), "--listen", f"tcp/127.0.0.1:{endpoint_port}", "--wait", "60",
            "--json", "--quiet", *options, stderr=subprocess.PIPE,
        )  # fmt: skip
        wait_port(endpoint_port, 60)
        with tap(f"tcp/127.0.0.1:{endpoint_port}") as session:

            def collect(sample: Any) -> None:
                key = str(sample.key_expr)
                # a stopping node of an earlier test may still be reconnecting to this port
                # (free_port can hand it out again): its ring is not play's
                if key.startswith(rings):
                    got.append((key, sample.payload.to_bytes()))

            subscriber = session.declare_subscriber("tokenring/**", collect)
            wait_until(lambda: len(got) >= expect or player.poll() not in (None, 0), 120, f"{expect} samples")
            if interrupt:
                player.send_signal(signal.SIGINT)
            out, err = player.communicate(timeout=120)
            if not interrupt:
                time.sleep(0.5)  # a sample on its way in after play's end would be one too many
            subscriber.undeclare()
    finally:
        leaked = tracker.cleanup()
    assert not leaked, leaked
    assert out.strip(), err
    return list(got), json.loads(out.strip().splitlines()[-1]), player.returncode


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_play_start_topics_ring_and_loop_do_what_their_help_says(capture: Capture) -> None:
    frames = recorded_frames(capture.path)
    start = recording_start(capture.path)
    span_s = (frames[-1].time_ns - start) / 1e9
    assert span_s > 2.0, f"the capture lasts only {span_s:.2f} s"

    # --start S: the frames recorded from S seconds in, and only those
    skip_s = round(span_s / 2, 1)
    wanted = [(f.key, f.payload) for f in frames if f.time_ns >= start + int(skip_s * 1e9)]
    got, summary, code = play_watched(
        capture.path, "--start", str(skip_s), "--rate", "4", ring=capture.ring, expect=len(wanted)
    )
    assert code == 0 and summary["frames"] == len(wanted)
    assert got == wanted, (len(got), len(wanted))
    assert 0 < len(got) < len(frames) - 100  # some seconds' frames left out at the start

    # --topics token/ID: only the frames passed to that node
    target = f"tokenring/{capture.ring}/token/{NODES['motor']}"
    wanted = [(f.key, f.payload) for f in frames if f.key == target]
    got, _, code = play_watched(
        capture.path,
        "--topics",
        f"token/{NODES['motor']}",
        "--rate",
        "8",
        ring=capture.ring,
        expect=len(wanted),
    )
    assert code == 0 and got == wanted and 0 < len(got) < len(frames)
    assert {payload[HEADER["did"]] for _, payload in got} == {NODES["motor"]}

    # --ring NAME: the same frames on the other ring's keys, none on the recorded ring's
    other = f"{capture.ring}x"
    wanted = [
        (f.key.replace(f"tokenring/{capture.ring}/", f"tokenring/{other}/"), f.payload)
        for f in frames
        if f.time_ns <= start + 1_000_000_000
    ]
    got, summary, code = play_watched(
        capture.path, "--ring", other, "--duration", "1", ring=capture.ring, expect=len(wanted)
    )
    assert code == 0 and summary["ring"] == other and summary["recorded_ring"] == capture.ring
    assert got == wanted and all(key.startswith(f"tokenring/{other}/token/") for key, _ in got)

    # --loop: the same stretch again and again until Ctrl-C
    stretch = [(f.key, f.payload) for f in frames if f.time_ns <= start + 500_000_000]
    got, summary, code = play_watched(
        capture.path,
        "--duration",
        "0.5",
        "--loop",
        "--rate",
        "2",
        ring=capture.ring,
        expect=2 * len(stretch) + 1,
        interrupt=True,
    )
    assert code == 130 and summary["loops"] >= 2, summary
    assert got[: len(stretch)] == stretch and got[len(stretch) : 2 * len(stretch)] == stretch
    assert got[2 * len(stretch)] == stretch[0]
