"""MCAP recording and playback (tokenring/observe/recording.py, ``record``, ``play``, ``up --record``,
``sniff --write/--read``, ``log convert --to mcap``).

The judge of every file is the ``mcap`` package's own reader (``make_reader``), never our
writer's code; the map in a recording is judged against ``tokenring map --out`` asked of the
live ring; a played recording is judged by ``sniff --json`` on the wire against ``sniff --read``
of the same file.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import NonSeekingReader, make_reader

from tests.support.processes import REPO, TOKENRING, run_tokenring
from tests.support.ringutil import launcher_pids, tap, wait_ring, wait_until
from tokenring.contract.protocol import default_protocol_path
from tokenring.host.pclink import PcLink
from tokenring.transport.session import free_port

PROTOCOL_TEXT = Path(default_protocol_path()).read_text()
NODES = ["main", "motor", "sonar", "compass", "copro", "map", "lcd", "charger"]


def read_mcap(path: Path) -> dict[str, Any]:
    """Channels (topic -> encoding, schema name, schema encoding, schema data, count), metadata,
    attachments and the messages of some topics, as the mcap package reads them."""
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        channels = {}
        for channel in summary.channels.values():
            schema = summary.schemas.get(channel.schema_id)
            channels[channel.topic] = {
                "encoding": channel.message_encoding,
                "schema": schema.name if schema else None,
                "schema_encoding": schema.encoding if schema else None,
                "schema_data": bytes(schema.data) if schema else b"",
                "count": summary.statistics.channel_message_counts.get(channel.id, 0),
            }
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        attachments = {a.name: bytes(a.data) for a in reader.iter_attachments()}
        return {"channels": channels, "metadata": metadata, "attachments": attachments}


def messages(path: Path, topic: str) -> list[tuple[int, Any]]:
    with open(path, "rb") as stream:
        return [
            (m.log_time, json.loads(m.data)) for _, _, m in make_reader(stream).iter_messages(topics=[topic])
        ]


def one_line_refusal(result: subprocess.CompletedProcess, *words: str) -> None:
    assert result.returncode == 2, (result.returncode, result.stdout, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    for word in words:
        assert word in lines[0], (word, lines[0])


def without_time(line: str) -> dict[str, Any]:
    record = json.loads(line)
    record.pop("t")
    return record


def enough_recorded(part: Path, ring: str, after_ns: int) -> bool:
    """True once a recording's part file holds more than the run's judgement below needs: frames,
    round trips and poses, every node's data channel, polls naming all eight nodes (most of
    those made while frames flowed), and frames from after ``after_ns`` (the map fetched then)."""
    counts: dict[str, int] = {}
    frames: list[int] = []
    polls: list[tuple[int, int]] = []  # (time, nodes named)
    with open(part, "rb") as stream:
        try:
            for _, channel, message in NonSeekingReader(stream).iter_messages(log_time_order=False):
                topic = channel.topic
                counts[topic] = counts.get(topic, 0) + 1
                if topic == "/ring/frame":
                    frames.append(message.log_time)
                elif topic == "/ring/nodes":
                    polls.append((message.log_time, len(json.loads(message.data)["nodes"])))
        except Exception:
            pass  # the torn tail, still being written
    raw = sum(n for topic, n in counts.items() if f"tokenring/{ring}/token/" in topic)
    if not frames or frames[-1] <= after_ns or raw < 1500:
        return False
    polled = [n for t, n in polls if frames[0] <= t <= frames[-1]]
    whole = sum(n == len(NODES) for n in polled)
    return (
        whole >= 15
        and whole >= 0.6 * len(polled)
        and counts.get("/ring/roundtrip", 0) > 20
        and min(counts.get("/robot/pose/true", 0), counts.get("/robot/pose/odometry", 0)) > 20
        and all(counts.get(f"/channel/{node}.data", 0) >= 1 for node in NODES)
    )


@pytest.mark.slow
@pytest.mark.timeout(420)
def test_up_record_holds_the_run_and_play_gives_sniff_the_same_frames(procs, ring_name, endpoint, tmp_path):
    """An exploring robot recorded by ``up --record`` at speed 5: schemas, counts, the
    map as ``tokenring map`` fetched it; then played into a fresh endpoint, ``sniff --json`` sees
    exactly the frames ``sniff --read`` decodes from the file."""
    recording = tmp_path / "run.mcap"
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--duration", "600", "--explore", "2",
        "--speed", "5", "--record", str(recording),
    )  # fmt: skip  # --duration: a hang guard (the run ends when exploring is stopped, below)
    vectors = [(100 + 10 * i, -50 * i, 300 + 10 * i, 70) for i in range(5)]  # cm on the wire
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20, 30, 40, 50, 60, 70, 80], timeout=120)
        procs.watch(launcher_pids(session, ring_name))
        link = PcLink(session, ring_name, timeout=10)
        for x1, y1, x2, y2 in vectors:  # vectors the map certainly holds, beside exploring's
            assert link.command("map", "VECTOR", x1=x1, y1=y1, x2=x2, y2=y2)["acknowledged"]
        wait_until(lambda: link.read("map.data")["vector_count"] >= 5, 30, "5 vectors in map.data")
        fetched = run_tokenring(
            "map", "--out", str(tmp_path / "m.json"), "--ring", ring_name, "-e", endpoint, timeout=120
        )
        assert fetched.returncode == 0, fetched.stdout + fetched.stderr
        fetched_at = time.time_ns()
        # the robot explores until FILE.part (flushed every second) holds what is judged below,
        # with some to spare; then exploring is stopped as --duration's end would, and the
        # mission ends the run itself (exit 0, the recording finalised)
        wait_until(lambda: link.request("state")["mode"] == 2, 120, "Explore 2 running (calibrated)")
        part = Path(f"{recording}.part")
        wait_until(
            lambda: enough_recorded(part, ring_name, fetched_at), 240, "enough of the run in FILE.part", 2
        )
        link.request("stop")
    out, _ = launcher.communicate(timeout=180)
    assert launcher.returncode == 0, out[-3000:]
    assert recording.exists() and not Path(f"{recording}.part").exists(), out[-3000:]

    got = read_mcap(recording)
    channels = got["channels"]
    meta = got["metadata"]["tokenring"]
    assert meta["ring"] == ring_name and meta["tokenring_version"]
    assert got["attachments"]["protocol.yaml"].decode() == PROTOCOL_TEXT
    import hashlib

    assert meta["protocol_sha256"] == hashlib.sha256(PROTOCOL_TEXT.encode()).hexdigest()
    for topic, channel in channels.items():
        if topic.startswith("/"):  # every JSON topic has its JSON Schema
            assert channel["encoding"] == "json" and channel["schema_encoding"] == "jsonschema", topic
            assert json.loads(channel["schema_data"])["type"] == "object", topic
        else:  # a raw Zenoh key of the ring
            assert topic.startswith(f"tokenring/{ring_name}/") and channel["encoding"] == "tokenring.zenoh"
    counts = {topic: c["count"] for topic, c in channels.items()}
    raw_frames = sum(n for topic, n in counts.items() if "/token/" in topic)
    assert raw_frames > 1000, counts
    assert counts["/ring/frame"] == raw_frames  # one header per frame recorded
    assert {f"tokenring/{ring_name}/token/{i}" for i in range(10, 90, 10)} <= set(counts)
    for node in NODES:
        assert counts.get(f"/channel/{node}.data", 0) >= 1, node
    assert counts["/ring/roundtrip"] > 10 and counts["/ring/nodes"] >= 5
    # /ring/nodes: the recorder, a service up before any node, reaches every node once they
    # are up: while frames flowed, its polls name all eight (each under its own ID and name,
    # its faults listed too) and main's visits advance from one poll to a later one
    ids = {str(10 * (i + 1)): name for i, name in enumerate(NODES)}
    frame_times = [t for t, _ in messages(recording, "/ring/frame")]
    polled = [d for t, d in messages(recording, "/ring/nodes") if frame_times[0] <= t <= frame_times[-1]]
    whole = [d for d in polled if set(d["nodes"]) == set(ids)]
    assert len(whole) >= 10 and len(whole) >= len(polled) // 2, [sorted(d["nodes"]) for d in polled]
    for poll in whole:
        assert {i: (s["id"], s["name"]) for i, s in poll["nodes"].items()} == {
            i: (int(i), name) for i, name in ids.items()
        }
    assert any(set(d["faults"]) == set(ids) for d in whole)
    assert whole[-1]["nodes"]["10"]["stats"]["visits"] > whole[0]["nodes"]["10"]["stats"]["visits"]
    assert counts["/robot/pose/true"] > 10 and counts["/robot/pose/odometry"] > 10, counts
    assert channels["/robot/pose/true"]["schema"] == "foxglove.PoseInFrame"
    pose = messages(recording, "/robot/pose/true")[-1][1]
    assert pose["frame_id"] == "room" and set(pose["pose"]["position"]) == {"x", "y", "z"}

    # the map: the file's map, as it stood when `tokenring map` asked, is the map it fetched
    wanted = json.loads((tmp_path / "m.json").read_text())["vectors"]
    assert len(wanted) >= 5
    states = [v["vectors"] for t, v in messages(recording, "/robot/map/vectors") if t <= fetched_at]
    assert any(
        len(state) == len(wanted)
        and all(
            abs(a - b) < 0.05
            for va, vb in zip(state, wanted, strict=True)
            for a, b in zip(va, vb, strict=True)
        )
        for state in states
    ), (wanted, states[-3:])

    # sniff --read: the file's frames decoded offline
    offline = run_tokenring("sniff", "--read", str(recording), "--json", timeout=300)
    assert offline.returncode == 0, offline.stderr
    expected = [without_time(line) for line in offline.stdout.splitlines()]
    assert len(expected) == raw_frames

    # play into a fresh endpoint, no ring behind it; sniff there sees the same frames
    play_endpoint = f"tcp/127.0.0.1:{free_port()}"
    player = procs.tokenring(
        "play", str(recording), "--listen", play_endpoint, "--rate", "5", "--wait", "60", "--json"
    )
    sniff = procs.tokenring(
        "sniff", "--ring", ring_name, "-e", play_endpoint, "--json", "--wait", "90",
        "-n", str(len(expected)), stderr=subprocess.PIPE,
    )  # fmt: skip
    live_out, live_err = sniff.communicate(timeout=300)
    assert sniff.returncode == 0, live_err
    played, _ = player.communicate(timeout=60)
    assert player.returncode == 0, played
    assert json.loads(played.strip().splitlines()[-1])["frames"] == raw_frames
    live = [without_time(line) for line in live_out.splitlines()]
    assert len(live) == len(expected)
    assert live == expected


@pytest.mark.slow
def test_refusals_are_one_line_and_exit_2(tmp_path, ring_name):
    existing = tmp_path / "exists.mcap"
    existing.write_bytes(b"keep me")
    not_mcap = tmp_path / "notes.mcap"
    not_mcap.write_text("hello\n")
    corrupt = tmp_path / "corrupt.mcap"
    corrupt.write_bytes(b"\x89MCAP0\r\n" + os.urandom(4000))
    port = free_port()
    one_line_refusal(run_tokenring("record", str(existing), "--ring", ring_name), "exists", "--force")
    assert existing.read_bytes() == b"keep me"
    one_line_refusal(
        run_tokenring("up", "--ring", ring_name, "--record", str(existing), "--duration", "5"),
        "--record",
        "exists",
    )
    one_line_refusal(
        run_tokenring("sniff", "--write", str(existing), "--ring", ring_name), "--write", "exists"
    )
    for bad, why in ((not_mcap, "not an MCAP file"), (corrupt, "not a readable MCAP file")):
        one_line_refusal(
            run_tokenring("play", str(bad), "--listen", f"tcp/127.0.0.1:{port}", "--wait", "0"), str(bad), why
        )
        one_line_refusal(run_tokenring("sniff", "--read", str(bad)), str(bad), why)
    one_line_refusal(run_tokenring("play", str(tmp_path / "missing.mcap")), "missing.mcap")
    result = run_tokenring("play", str(not_mcap), "--rate", "0")
    assert result.returncode == 2 and "Traceback" not in result.stderr


@pytest.mark.slow
def test_a_killed_recorder_leaves_its_part_file_readable_and_no_final_file(tmp_path):
    """A recorder killed outright: FILE never appears; FILE.part holds every message flushed
    before the kill, and the mcap package's streaming reader reads them."""
    script = """
import sys, time
from tokenring.observe.feed import Message, Topic
from tokenring.observe.recording import McapRecorder
rec = McapRecorder(sys.argv[1], ring="r", topics=[Topic("/n", "test.N", {"type": "object"})],
                   flush_interval_s=0.05)
for i in range(200):
    rec.on_message(Message("/n", 1_000_000_000 + i, {"i": i}))
    time.sleep(0.001)
time.sleep(0.1)
rec.tick()
print("written", flush=True)
time.sleep(60)
"""
    target = tmp_path / "killed.mcap"
    proc = subprocess.Popen(
        [TOKENRING[0], "-c", script, str(target)],
        stdout=subprocess.PIPE,
        text=True,
        cwd=REPO,
    )
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "written"
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
        if proc.stdout is not None:
            proc.stdout.close()
    assert not target.exists()
    part = Path(f"{target}.part")
    seen = []
    with open(part, "rb") as stream:
        try:
            for _, channel, message in NonSeekingReader(stream).iter_messages(log_time_order=False):
                assert channel.topic == "/n"
                seen.append(json.loads(message.data)["i"])
        except Exception:
            pass  # the torn tail (no footer): everything before it was read
    assert seen == list(range(200))
    # and play/sniff take it as it is
    result = run_tokenring("sniff", "--read", str(part))
    assert result.returncode == 2 and "no frames recorded" in result.stderr


@pytest.mark.slow
def test_a_trlog_converts_to_mcap(tmp_path):
    from modules.localization.logs import DataLog, ErrorLog

    path = tmp_path / "run.trlog"
    with DataLog(path, "20040120-130535", {"sensors": {}}) as log:
        for i in range(30):
            stamp = 100 * i
            log.write(stamp, "O", "R", {"gen": i, "n": 0, "v": {"steps_left": i, "steps_right": 2 * i}})
            log.write(stamp, "O", "P", {"x": 1000.0 + i, "y": 500.0, "psi": 0.0, "valid": [True] * 3})
            log.write(stamp, "T", "P", {"x": 1000.0 + i, "y": 501.0, "psi": 0.01, "valid": [True] * 3})
            if i % 3 == 0:
                log.write(
                    stamp, "K", "P",
                    {"x": 1002.0 + i, "y": 499.0, "psi": 0.02, "valid": [True] * 3, "sigma": [12.0, 8.0, 0.05]},
                )  # fmt: skip
    out = tmp_path / "run.mcap"
    result = run_tokenring("log", "convert", str(path), "--to", "mcap", "--out", str(out))
    assert result.returncode == 0, result.stderr
    got = read_mcap(out)
    counts = {topic: c["count"] for topic, c in got["channels"].items()}
    assert counts == {
        "/log/odometry/raw": 30,
        "/log/odometry/position": 30,
        "/log/truth/position": 30,
        "/log/filter/position": 10,
        "/robot/pose/odometry": 30,
        "/robot/pose/true": 30,
        "/robot/pose/filtered": 10,
        "/robot/tf": 10,
        "/robot/uncertainty": 10,
    }
    channels = got["channels"]
    assert channels["/robot/pose/true"]["schema"] == "foxglove.PoseInFrame"
    assert channels["/robot/tf"]["schema"] == "foxglove.FrameTransform"
    assert all(c["schema_encoding"] == "jsonschema" and c["encoding"] == "json" for c in channels.values())
    true = messages(out, "/robot/pose/true")
    assert true[3][1]["pose"]["position"] == {"x": 1.003, "y": 0.501, "z": 0.0}
    # time: the log's start (UTC) plus each record's stamp
    start = 1074603935 * 1_000_000_000  # 2004-01-20 13:05:35 UTC (calendar.timegm)
    assert [t for t, _ in true[:3]] == [start, start + 100_000_000, start + 200_000_000]
    sigma = messages(out, "/robot/uncertainty")[0][1]
    assert (sigma["sigma_x_m"], sigma["sigma_y_m"], sigma["sigma_theta_rad"]) == (0.012, 0.008, 0.05)
    assert messages(out, "/log/odometry/raw")[5][1]["v"] == {"steps_left": 5, "steps_right": 10}

    errors = tmp_path / "run.trerr"
    with ErrorLog(errors, "20040120-130535") as log:
        log.message("W", 10, "compass late")
        log.message("E", 20, "sonar lost")
    result = run_tokenring("log", "convert", str(errors), "--to", "mcap", "--out", str(tmp_path / "e.mcap"))
    assert result.returncode == 0, result.stderr
    logged = [m for _, m in messages(tmp_path / "e.mcap", "/log/errors")]
    assert [(m["level"], m["message"]) for m in logged] == [(3, "compass late"), (4, "sonar lost")]
    assert read_mcap(tmp_path / "e.mcap")["channels"]["/log/errors"]["schema"] == "foxglove.Log"
    # an existing output without --force, and a missing --out
    one_line_refusal(run_tokenring("log", "convert", str(path), "--to", "mcap", "--out", str(out)), "exists")
    one_line_refusal(run_tokenring("log", "convert", str(path), "--to", "mcap"), "--out")


def write_token_frames(path: Path, ring: str, frames: int) -> Path:
    """A recording of ``frames`` synthetic passes 1 ms apart, counters 0, 1, ... mod 256."""
    from tokenring.contract.frame import Token
    from tokenring.observe.feed import RawSample
    from tokenring.observe.recording import McapRecorder

    recorder = McapRecorder(path, ring=ring)
    for i in range(frames):
        token = Token()
        token["sid"], token["did"], token["counter"] = 10 * (i % 8 + 1), 10 * ((i + 1) % 8 + 1), i % 256
        recorder.on_raw(
            RawSample(
                f"tokenring/{ring}/token/{token['did']}", 1_000_000_000 + i * 1_000_000, token.to_frame()
            )
        )
    recorder.close()
    return path


@pytest.mark.slow
def test_play_waits_for_a_sniff_that_stalls_and_the_sniff_loses_no_frame(procs, tmp_path):
    """A sniff frozen for 6 s while play sends (longer than the 5 s Zenoh waits on a blocked link
    before closing it) still gets every frame: play waits on it, and before closing its session
    asks every sniff whether it has taken the last frame."""
    ring, frames = "stall", 20000
    recording = write_token_frames(tmp_path / "frames.mcap", ring, frames)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    player = procs.tokenring(
        "play", str(recording), "--listen", endpoint, "--rate", "5", "--wait", "60", "--json"
    )
    sniffed = tmp_path / "sniffed.jsonl"
    with sniffed.open("w") as out:
        sniff = procs.tokenring(
            "sniff", "--ring", ring, "-e", endpoint, "--json", "--wait", "90", "-n", str(frames), stdout=out
        )
        wait_until(lambda: sniffed.stat().st_size > 0, 60, "the sniff's first frame")
        os.kill(sniff.pid, signal.SIGSTOP)
        time.sleep(6.0)  # the fault: a sniff that reads nothing for 6 s (Zenoh's lease is 10 s)
        os.kill(sniff.pid, signal.SIGCONT)
        played, _ = player.communicate(timeout=180)
        assert player.returncode == 0, played
        summary = json.loads(played.strip().splitlines()[-1])
        assert summary["frames"] == frames and summary["taps_drained"] == 1, summary
        sniff.wait(timeout=120)
    assert sniff.returncode == 0
    lines = sniffed.read_text().splitlines()
    assert len(lines) == frames
    assert [json.loads(line)["header"]["counter"] for line in lines] == [i % 256 for i in range(frames)]


@pytest.mark.slow
def test_play_reports_a_sniff_whose_link_zenoh_cut_even_when_it_came_back(procs, tmp_path):
    """A sniff frozen for 8 s while play sends 30 MB, with play waiting at most 1 s on it: the
    link's buffers fill, Zenoh cuts the link and drops what was queued. Whether the sniff comes
    back before the end (and confirms the last frame) or not, play names it and exits 1, and the
    sniff did miss frames."""
    ring, frames = "cut", 60000
    recording = write_token_frames(tmp_path / "frames.mcap", ring, frames)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    player = procs.tokenring(
        "play", str(recording), "--listen", endpoint, "--rate", "5", "--wait", "60", "--slow-wait", "1",
        "--json",
    )  # fmt: skip
    sniffed = tmp_path / "sniffed.jsonl"
    with sniffed.open("w") as out:
        sniff = procs.tokenring("sniff", "--ring", ring, "-e", endpoint, "--json", "--wait", "90", stdout=out)
        wait_until(lambda: sniffed.stat().st_size > 0, 60, "the sniff's first frame")
        os.kill(sniff.pid, signal.SIGSTOP)
        time.sleep(8.0)  # the fault: 20 MB sent meanwhile, far more than the link buffers
        os.kill(sniff.pid, signal.SIGCONT)
        played, _ = player.communicate(timeout=180)
        sniff.kill()  # its router (play) is gone: only the output it wrote is judged
        sniff.wait(timeout=30)
    summary = json.loads(played.strip().splitlines()[-1])
    assert player.returncode == 1, played
    assert len(summary["taps_lost"]) == 1, summary
    assert len(sniffed.read_text().splitlines()) < frames  # the judge: frames did go missing


@pytest.mark.slow
def test_play_does_not_report_a_sniff_that_stopped_on_purpose(procs, tmp_path):
    """A sniff that stops after 100 frames (-n) while play goes on lost nothing it wanted: play
    exits 0 and names no tap lost."""
    ring = "early"
    recording = write_token_frames(tmp_path / "frames.mcap", ring, 5000)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    player = procs.tokenring("play", str(recording), "--listen", endpoint, "--wait", "60", "--json")
    sniff = procs.tokenring("sniff", "--ring", ring, "-e", endpoint, "--json", "--wait", "90", "-n", "100")
    sniffed, _ = sniff.communicate(timeout=120)
    assert sniff.returncode == 0 and len(sniffed.splitlines()) == 100
    played, _ = player.communicate(timeout=120)
    summary = json.loads(played.strip().splitlines()[-1])
    assert player.returncode == 0, played
    assert summary["taps_lost"] == [] and summary["frames"] == 5000, summary


def test_a_tap_is_named_alike_in_its_token_its_drain_reply_and_its_goodbye():
    from tokenring.contract import keys

    assert keys.tap_id_from_key("tokenring/r/tap/ab12") == "ab12"
    assert keys.tap_id_from_key("tokenring/r/tap/ab12/drained") == "ab12"
    assert keys.tap_id_from_key("tokenring/r/tap/ab12/left") == "ab12"
    assert keys.tap_id_from_key("tokenring/r/node/20") is None
    assert keys.tap_id_from_key("other/r/tap/ab12") is None
    # the keys a sniff declares and puts parse back to the ID it made them with
    for key in (keys.tap("r", "ab12"), keys.tap_drained("r", "ab12"), keys.tap_left("r", "ab12")):
        assert keys.tap_id_from_key(key) == "ab12", key
