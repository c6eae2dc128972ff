"""Captures Wireshark opens (issue 56): ``sniff --write FILE.pcapng``, ``record --pcap`` and the
Lua dissector ``tokenring dissector`` generates, judged by tshark (Debian's package) and by
``sniff --json``, never by the writer's or the generator's own code.

The live ring is a system of the test's own, not the robot (the dissector comes from whatever
protocol.yaml is loaded): two nodes whose programs rally a ball over their inboxes and publish
integers, an enum, text, arrays, a 64-bit counter and floats. The ring boots with ``--no-start``;
``sniff --json --write F.pcapng`` starts, then ``tokenring load -a --start`` downloads both
programs over the ring and starts them, so the capture holds system commands (scan, config,
downloads, start), commands with arguments and every kind of field; Ctrl-C ends the capture.

For every frame, what tshark prints with the dissector (``-T json``) equals what sniff printed
for it: header, system command, CRC verdict, each channel's values (Wireshark's own rendering
aside: a float to its 6 (f32) or 15 (f64) significant digits, text up to its first NUL). Without
the dissector tshark shows the ARCNET header (source and destination IDs, the interface named by
the Zenoh key, the time stamp to the nanosecond). A second judgement drives the robot's own
protocol.yaml with frames of random bytes (every field of every channel, commands of every
code, each system command's window) and damaged frames through the same comparison.
"""

from __future__ import annotations

import json
import os
import random
import shutil
import signal
import subprocess
import time
import uuid
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.support.processes import REPO, TOKENRING, Processes, run_tokenring
from tests.support.ringjudge import crc16_arc  # the judge's own CRC, not tokenring's
from tests.support.ringutil import launcher_pids, tap, wait_ring, wait_until
from tokenring.transport.session import free_port

pytestmark = pytest.mark.xdist_group("wireshark")  # one ring for the module's live tests

PINGPONG_PROTOCOL = REPO / "tests" / "pingpong" / "protocol.yaml"
NODES = {"main": 10, "pong": 20}
RALLIES = 8  # rallies seen on the wire before the capture ends

MAIN_PROGRAM = '''"""Serves the ball to pong, counts the rallies in its data channel."""

from tokenring import UserProgram


class Program(UserProgram):
    def setup(self):
        self.os.set_own_input_id()
        self.score = self.os.publish()

    def run(self):
        n, rallies = 1, 0
        while self.running:
            if not self.os.deliver("pong", "BALL", n=n, spin=-(n % 300), timeout=2.0):
                continue
            answer = self.os.receive_command(timeout=5.0)
            if answer is None or answer.name != "BALL":
                continue
            rallies += 1
            self.score.write(
                rallies=rallies, ratio=rallies / 3, mood=rallies % 3, tag=f"r{rallies}"[:8],
                recent=[n % 30000, -(n % 30000), rallies % 7],
            )
            n = answer.args["n"] + 1
'''

PONG_PROGRAM = '''"""Returns the ball to main as n + 1, and says so in a NOTE now and then."""

from tokenring import UserProgram


class Program(UserProgram):
    def setup(self):
        self.os.set_own_input_id()
        self.score = self.os.publish()

    def run(self):
        returned, total = 0, 0
        while self.running:
            ball = self.os.receive_command(timeout=0.2)
            if ball is None or ball.name != "BALL":
                continue
            if not self.os.deliver("main", "BALL", n=ball.args["n"] + 1, spin=ball.args["spin"], timeout=30.0):
                continue
            returned += 1
            total += ball.args["n"] + 2**40
            self.score.write(returned=returned, total=total, mood=returned % 3, half=returned / 2)
'''


def write_system(folder: Path) -> Path:
    """The test's protocol.yaml (the pingpong example's token, nodes of our own) and programs."""
    doc = yaml.safe_load(PINGPONG_PROTOCOL.read_text())
    doc["enums"]["mood"] = {"CALM": 0, "HAPPY": 1, "ANGRY": 2}
    ball = {"code": 1, "args": {"n": "u32", "spin": "i16"}}
    doc["nodes"] = {
        "main": {
            "id": NODES["main"],
            "command": {"address": 12, "size": 16, "commands": {"BALL": ball}},
            "data": {"address": 28, "size": 24, "fields": {
                "rallies": "u32", "ratio": "f32", "mood": {"type": "u8", "enum": "mood"},
                "tag": "str[8]", "recent": "i16[3]",
            }},
        },
        "pong": {
            "id": NODES["pong"],
            "command": {"address": 52, "size": 16, "commands": {
                "BALL": ball, "NOTE": {"code": 2, "args": {"text": "str[7]"}},
            }},
            "data": {"address": 68, "size": 24, "fields": {
                "returned": "u32", "total": "u64", "mood": {"type": "u8", "enum": "mood"},
                "half": {"type": "f64", "unit": "balls"},
            }},
        },
    }  # fmt: skip
    path = folder / "protocol.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    (folder / "programs").mkdir()
    (folder / "programs" / "main.py").write_text(MAIN_PROGRAM)
    (folder / "programs" / "pong.py").write_text(PONG_PROGRAM)
    return path


# --------------------------------------------------------------------------------------------
# tshark


def tshark_path() -> str:
    found = shutil.which("tshark")
    if found is None:
        pytest.fail("tshark is not installed (Debian package tshark; .ci/run installs it)")
    return found


def tshark(home: Path, *args: str) -> str:
    """tshark's output; its own settings folder (a personal plugin folder holding another
    tokenring.lua would register the protocol twice), no name lookups. Run as root (CI), tshark
    warns on stderr and goes on; it never prompts."""
    home.mkdir(exist_ok=True)
    env = dict(os.environ, HOME=str(home), XDG_CONFIG_HOME=str(home / ".config"))
    result = subprocess.run(
        [tshark_path(), "-n", *args], capture_output=True, text=True, timeout=600, env=env
    )
    assert result.returncode == 0, result.stderr[-2000:]
    assert "Lua: Error" not in result.stderr and "lua_script" not in result.stderr, result.stderr[-2000:]
    return result.stdout


def flatten(node: dict[str, Any], out: dict[str, Any]) -> dict[str, Any]:
    """Every ``tokenring.*`` field of a packet's tokenring layer, subtrees flattened."""
    for key, value in node.items():
        if isinstance(value, dict):
            flatten(value, out)
        elif key.startswith("tokenring."):
            out[key] = value
    return out


def dissected(home: Path, capture: Path, lua: Path) -> list[dict[str, Any]]:
    """Each packet's tokenring fields as tshark prints them with the dissector (``-T json``,
    duplicate keys merged into lists: an array's elements)."""
    text = tshark(home, "-X", f"lua_script:{lua}", "-r", str(capture), "-T", "json", "--no-duplicate-keys")
    packets = json.loads(text)
    return [flatten(p["_source"]["layers"].get("tokenring", {}), {}) for p in packets]


def expected_fields(record: dict[str, Any]) -> dict[str, Any]:
    """What tshark's fields must hold for one ``sniff --json`` record."""
    out: dict[str, Any] = {
        "tokenring.length": record["length"],
        "tokenring.ok": record["ok"],
        "tokenring.crc_ok": record["crc_ok"],
    }
    if "problem" in record:
        out["tokenring.problem"] = record["problem"]
    for name, value in record.get("header", {}).items():
        out[f"tokenring.{name}"] = value
    if "crc" in record:
        out["tokenring.crc"] = record["crc"]
    for channel, fields in record.get("channels", {}).items():
        for name, value in fields.items():
            if name == "args":
                for arg, arg_value in value.items():
                    out[f"tokenring.{channel}.{fields['command']}.{arg}"] = arg_value
            else:
                out[f"tokenring.{channel}.{name}"] = value
    return out


def same(expected: Any, shown: Any) -> bool:
    """Whether tshark's text shows ``expected`` (sniff's value) as Wireshark renders it."""
    if isinstance(expected, bool):
        return shown == ("1" if expected else "0")
    if isinstance(expected, int):
        return int(shown, 0) == expected  # (the CRC in hex)
    if isinstance(expected, float):  # FT_FLOAT to 6 significant digits, FT_DOUBLE to 15
        return float(shown) in (float(f"{expected:.6g}"), float(f"{expected:.15g}"))
    if isinstance(expected, str):  # Wireshark's strings end at the first NUL
        return shown == expected.split("\0", 1)[0]
    if isinstance(expected, list):
        shown = shown if isinstance(shown, list) else [shown]
        return len(shown) == len(expected) and all(same(e, s) for e, s in zip(expected, shown, strict=True))
    raise AssertionError(f"unexpected value {expected!r}")


def zero(shown: Any) -> bool:
    values = shown if isinstance(shown, list) else [shown]
    return all(value == "" or float(value) == 0 for value in values)


def compare(records: list[dict[str, Any]], packets: list[dict[str, Any]]) -> list[str]:
    """Differences between what sniff printed and what tshark shows, frame by frame: every
    value sniff printed, and nothing sniff did not print but the channels it leaves out for
    being all 0 (tshark shows them, all 0) and the system command's window (sniff has none)."""
    assert len(packets) == len(records), (len(packets), len(records))
    problems = []
    for index, (record, shown) in enumerate(zip(records, packets, strict=True)):
        expected = expected_fields(record)
        for name, value in expected.items():
            if name not in shown or not same(value, shown[name]):
                problems.append(f"frame {index + 1}: {name} sniff {value!r}, tshark {shown.get(name)!r}")
        printed = set(record.get("channels", {}))
        for name, value in shown.items():
            parts = name.split(".")
            if name in expected or parts[1] == "system":
                continue
            channel = ".".join(parts[1:3])
            decoded = parts[2:3] == ["command"] and (len(parts) == 5 or parts[3:] == ["command"])
            if decoded or channel in printed or not zero(value):
                problems.append(f"frame {index + 1}: tshark shows {name} = {value!r}, sniff does not")
    return problems


def nanoseconds(epoch: str) -> int:
    """tshark's ``frame.time_epoch`` (``1700000000.123456789``) in ns, exactly."""
    seconds, _, fraction = epoch.partition(".")
    return int(seconds) * 10**9 + int(fraction.ljust(9, "0")[:9])


# --------------------------------------------------------------------------------------------
# the live ring and its capture


@dataclass
class Live:
    ring: str
    endpoint: str
    protocol: Path
    folder: Path
    capture: Path
    lines: list[str]  # what sniff --json printed
    stderr: str
    returncode: int
    lua: Path

    @property
    def records(self) -> list[dict[str, Any]]:
        return [json.loads(line) for line in self.lines]


def printed(path: Path) -> list[dict[str, Any]]:
    """The whole lines sniff has printed so far."""
    text = path.read_text() if path.exists() else ""
    return [json.loads(line) for line in text.splitlines(keepends=True) if line.endswith("\n")]


def rallied(path: Path) -> bool:
    """sniff has printed a frame whose main.data says RALLIES rallies."""
    return any(
        r.get("channels", {}).get("main.data", {}).get("rallies", 0) >= RALLIES for r in printed(path)[-400:]
    )


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Live]:
    folder = tmp_path_factory.mktemp("wireshark")
    protocol = write_system(folder)
    ring = f"t{uuid.uuid4().hex[:10]}"
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    ring_options = ["--ring", ring, "-e", endpoint, "--protocol", str(protocol)]
    env = {"TOKENRING_EXTENSIONS": ""}  # the ring alone: no robot, no world
    tracker = Processes()
    try:
        up_log = folder / "up.log"
        launcher = tracker.tokenring(
            "up", "--ring", ring, "--listen", endpoint, "--protocol", str(protocol),
            "--programs", str(folder / "programs"), "--store", str(folder / "store"), "--no-start",
            "--duration", "600", env=env, stdout=up_log.open("w"),
        )  # fmt: skip
        with tap(endpoint) as session:
            wait_ring(session, ring, list(NODES.values()), timeout=120)
            tracker.watch(launcher_pids(session, ring))
        wait_until(lambda: "programs wait" in up_log.read_text(), 120, "the launcher's --no-start line")
        capture, out, err = folder / "live.pcapng", folder / "sniff.jsonl", folder / "sniff.err"
        sniff = tracker.tokenring(
            "sniff", *ring_options, "--json", "--write", str(capture), "--wait", "60",
            env=env, stdout=out.open("w"), stderr=err.open("w"),
        )  # fmt: skip
        wait_until(lambda: printed(out), 60, "sniff's first frame")
        load = run_tokenring(
            "load", "-a", "--start", "--programs", str(folder / "programs"), "--no-progress", *ring_options,
            timeout=180, env=dict(os.environ, **env),
        )  # fmt: skip
        assert load.returncode == 0, load.stdout + load.stderr
        wait_until(lambda: rallied(out), 120, f"{RALLIES} rallies on the wire", interval=0.5)
        sniff.send_signal(signal.SIGINT)  # Ctrl-C: the capture ends between two frames
        assert sniff.wait(60) == 130
        lua = folder / "tokenring.lua"
        with lua.open("w") as script:
            made = subprocess.run(
                [*TOKENRING, "dissector", "--protocol", str(protocol)],
                stdout=script, stderr=subprocess.PIPE, text=True, timeout=60,
            )  # fmt: skip
        assert made.returncode == 0, made.stderr
        yield Live(
            ring, endpoint, protocol, folder, capture, out.read_text().splitlines(), err.read_text(),
            sniff.returncode, lua,
        )  # fmt: skip
        launcher.send_signal(signal.SIGTERM)
        assert launcher.wait(60) in (0, 130), up_log.read_text()[-3000:]
    finally:
        leaked = tracker.cleanup()
    assert not leaked, leaked


@pytest.mark.slow
@pytest.mark.timeout(600)  # the module's ring, its programs' download and the capture
def test_tshark_shows_every_frame_as_sniff_printed_it(live: Live, tmp_path: Path) -> None:
    records = live.records
    assert f"{live.capture}: {len(records)} frames captured" in live.stderr, live.stderr
    packets = dissected(tmp_path / "home", live.capture, live.lua)
    problems = compare(records, packets)
    assert not problems, "\n".join(problems[:30])
    # the capture holds what it is for: the download's system commands, commands with their
    # arguments, and every kind of field with values in it
    names = {r["header"]["syscmd_code_name"] for r in records}
    assert {"ARCNET_SCAN", "ARCNET_DOWNLOAD_BEGIN", "ARCNET_DOWNLOAD_DATA", "ARCNET_START_SYSTEM"} <= names, (
        names
    )
    shown_names = {p["tokenring.syscmd_code_name"] for p in packets}
    assert names == shown_names
    assert any("tokenring.system.ARCNET_DOWNLOAD_DATA.request.chunk" in p for p in packets)
    balls = [p for p in packets if p.get("tokenring.pong.command.command") == "BALL"]
    assert balls and all("tokenring.pong.command.BALL.spin" in p for p in balls)
    last = packets[-1]
    assert int(last["tokenring.main.data.rallies"]) >= RALLIES and last["tokenring.main.data.tag"].startswith(
        "r"
    )
    assert float(last["tokenring.main.data.ratio"]) > 0 and int(last["tokenring.pong.data.total"]) > 2**40


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_without_the_dissector_tshark_shows_the_arcnet_header(live: Live, tmp_path: Path) -> None:
    records = live.records
    fields = ["frame.interface_name", "frame.time_epoch", "frame.protocols", "arcnet.src", "arcnet.dst",
              "arcnet.protID", "arcnet.offset", "data.len"]  # fmt: skip
    text = tshark(
        tmp_path / "home", "-r", str(live.capture), "-T", "fields", *[a for f in fields for a in ("-e", f)]
    )
    rows = [dict(zip(fields, line.split("\t"), strict=True)) for line in text.splitlines()]
    assert len(rows) == len(records)
    stamps = []
    for row, record in zip(rows, records, strict=True):
        assert row["frame.protocols"] == "arcnet:data", row
        assert row["frame.interface_name"] == f"tokenring/{live.ring}/token/{record['key_did']}"
        assert int(row["arcnet.src"], 16) == record["header"]["sid"]
        assert int(row["arcnet.dst"], 16) == record["header"]["did"]
        assert int(row["arcnet.protID"], 16) == 0x54 and row["arcnet.offset"].replace(":", "") == "0004"
        assert int(row["data.len"]) == record["length"] == 514
        stamp = nanoseconds(row["frame.time_epoch"])
        assert stamp / 1e9 == record["t"]  # the time sniff printed, to the nanosecond
        stamps.append(stamp)
    assert sum(s % 1000 != 0 for s in stamps) > len(stamps) / 2  # nanoseconds, not microseconds


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_sniff_read_of_the_capture_prints_what_sniff_printed_live(live: Live) -> None:
    offline = run_tokenring("sniff", "--read", str(live.capture), "--json", "--protocol", str(live.protocol))
    assert offline.returncode == 0 and offline.stderr == "", offline.stderr
    assert offline.stdout.splitlines() == live.lines
    one = run_tokenring(
        "sniff", "--read", str(live.capture), "--protocol", str(live.protocol), "--to", "20", "-n", "3"
    )
    assert one.returncode == 0 and len(one.stdout.splitlines()) == 3, one.stderr
    assert all("->20 " in line for line in one.stdout.splitlines()), one.stdout


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_record_pcap_writes_the_frames_wireshark_opens(live: Live, tmp_path: Path) -> None:
    """``record --pcap`` alone, and beside an MCAP recording of the same ring: tshark shows
    what sniff reads, and where the two files' times overlap they hold the same frames."""
    options = ["--ring", live.ring, "-e", live.endpoint, "--protocol", str(live.protocol)]
    env = dict(os.environ, TOKENRING_EXTENSIONS="")
    home = tmp_path / "home"
    alone, both, mcap = tmp_path / "alone.pcapng", tmp_path / "both.pcapng", tmp_path / "run.mcap"
    for command in (["--pcap", str(alone)], [str(mcap), "--pcap", str(both)]):
        result = run_tokenring(
            "record", *command, "--duration", "2", "--json", *options, env=env, timeout=120
        )
        assert result.returncode == 0, result.stderr
        summary = json.loads(result.stdout)["pcap"]
        capture = Path(summary["file"])
        assert summary["frames"] > 50 and summary["failure"] is None, summary
        assert summary["bytes"] == capture.stat().st_size
        read = run_tokenring("sniff", "--read", str(capture), "--json", "--protocol", str(live.protocol))
        assert read.returncode == 0, read.stderr
        records = [json.loads(line) for line in read.stdout.splitlines()]
        assert len(records) == summary["frames"]
        problems = compare(records, dissected(home, capture, live.lua))
        assert not problems, "\n".join(problems[:30])
    from mcap.reader import make_reader

    with mcap.open("rb") as stream:
        recorded = {bytes(m.data) for _, c, m in make_reader(stream).iter_messages() if "/token/" in c.topic}
    captured = [
        bytes.fromhex(line)
        for line in tshark(home, "-r", str(both), "-T", "fields", "-e", "data.data").split()
    ]
    assert len(recorded) > 50 and sum(f in recorded for f in captured) >= 0.8 * min(
        len(captured), len(recorded)
    )


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_the_watcher_captures_beside_its_metrics_on_its_own_feed(live: Live, tmp_path: Path) -> None:
    """``watch --metrics --pcap`` (what ``up --metrics P --pcap F`` starts): one process, one
    subscription to the frames, and the capture is what tshark and sniff read."""
    options = ["--ring", live.ring, "-e", live.endpoint, "--protocol", str(live.protocol)]
    env = dict(os.environ, TOKENRING_EXTENSIONS="")
    capture = tmp_path / "watched.pcapng"
    result = run_tokenring(
        "watch", "--metrics", "0", "--pcap", str(capture), "--duration", "2", *options, env=env, timeout=120
    )
    assert result.returncode == 0, result.stderr
    assert "metrics of ring" in result.stdout and f"{capture}: " in result.stdout, result.stdout
    read = run_tokenring("sniff", "--read", str(capture), "--json", "--protocol", str(live.protocol))
    assert read.returncode == 0, read.stderr
    records = [json.loads(line) for line in read.stdout.splitlines()]
    assert len(records) > 50, len(records)
    assert {r["header"]["sid"] for r in records} == set(NODES.values())  # frames only, every node's
    problems = compare(records, dissected(tmp_path / "home", capture, live.lua))
    assert not problems, "\n".join(problems[:30])


# --------------------------------------------------------------------------------------------
# every field of the robot's protocol.yaml, and damaged frames (no ring)


def random_frames(count: int, seed: int) -> list[tuple[str, bytes]]:
    """(key, frame) pairs for the default protocol.yaml: random tokens, sealed, with the header's
    constant bytes, known command codes in some inboxes and a system command in some; then the
    damaged ones (CRC, marker, length, a DID byte the key does not name)."""
    from tokenring.contract.protocol import default_protocol

    protocol = default_protocol()
    header = protocol.header.offsets
    rng = random.Random(seed)
    frames = []
    for index in range(count):
        token = bytearray(rng.randbytes(protocol.token_size))
        for name, value in protocol.header.consts.items():
            token[header[name]] = value
        for node in protocol.nodes.values():
            inbox = node.command
            if rng.random() < 0.5:
                code_at = inbox.address + next(f.offset for f in inbox.fields if f.name == "code")
                token[code_at] = rng.choice(sorted(inbox.by_code))
        if index % 3:
            token[header["syscmd_code"]] = rng.choice(sorted(protocol.system_commands.values()))
            token[header["syscmd_ack"]] = rng.choice([0, 0, token[header["syscmd_ack"]]])
        crc = crc16_arc(bytes(token))
        did = token[header["did"]]
        frames.append((f"tokenring/r/token/{did}", bytes(token) + bytes((crc & 0xFF, crc >> 8))))
    good = frames[0][1]
    bad_crc = bytearray(good)
    bad_crc[200] ^= 0x10
    bad_marker = bytearray(good[:512])
    bad_marker[header["size_marker"]] = 2
    crc = crc16_arc(bytes(bad_marker))
    misaddressed = bytearray(good)
    frames += [
        ("tokenring/r/token/7", bytes(bad_crc)),
        ("tokenring/r/token/7", bytes(bad_marker) + bytes((crc & 0xFF, crc >> 8))),
        ("tokenring/r/token/7", good[:100]),
        ("tokenring/r/token/7", good + b"\0" * 20),
        ("tokenring/r/token/1", bytes(misaddressed)),
    ]
    return frames


def write_capture(
    path: Path, frames: list[tuple[str, bytes]], protocol_path: Path | None = None
) -> list[int]:
    """The frames written by tokenring's pcapng writer (what sniff --write uses); their times."""
    from tokenring.contract.protocol import default_protocol, load_protocol
    from tokenring.observe.feed import RawSample
    from tokenring.observe.pcapng import PcapngWriter

    protocol = load_protocol(protocol_path) if protocol_path else default_protocol()
    writer = PcapngWriter(path, ring="r", protocol=protocol)
    times = []
    start = time.time_ns()
    for index, (key, frame) in enumerate(frames):
        times.append(start + index * 1_000_003)
        writer.on_raw(RawSample(key, times[-1], frame))
    writer.close()
    return times


@pytest.mark.slow
def test_every_field_of_the_robots_protocol_and_damaged_frames(tmp_path: Path) -> None:
    from tokenring.contract.protocol import default_protocol

    protocol = default_protocol()
    frames = random_frames(240, seed=56)
    capture = tmp_path / "random.pcapng"
    write_capture(capture, frames)
    lua = tmp_path / "tokenring.lua"
    made = run_tokenring("dissector")
    assert made.returncode == 0, made.stderr
    lua.write_text(made.stdout)
    read = run_tokenring("sniff", "--read", str(capture), "--json")
    assert read.returncode == 0, read.stderr
    records = [json.loads(line) for line in read.stdout.splitlines()]
    assert [r["key_did"] for r in records] == [int(k.rsplit("/", 1)[1]) for k, _ in frames]
    packets = dissected(tmp_path / "home", capture, lua)
    problems = compare(records, packets)
    assert not problems, "\n".join(problems[:30])
    assert [r.get("problem") for r in records[-5:]] == ["crc", "marker", "length", "length", None]
    assert [p.get("tokenring.problem") for p in packets[-5:]] == ["crc", "marker", "length", "length", None]
    # every channel's every field was shown with values in it, and commands of every code
    seen = set().union(*packets)
    for channel in protocol.channels.values():
        for spec in channel.fields:
            assert f"tokenring.{channel.name}.{spec.name}" in seen
    for node in protocol.nodes.values():
        inbox = node.command.name
        shown_commands = {p.get(f"tokenring.{inbox}.command") for p in packets}
        assert set(node.command.commands) <= shown_commands, (inbox, shown_commands)
        for command in node.command.commands.values():
            assert all(f"tokenring.{inbox}.{command.name}.{a.name}" in seen for a in command.args)
    # each system command's window: the request (the answer once acknowledged, where it has
    # one), judged by the test's own reading of protocol.yaml's layout
    import struct

    layout = yaml.safe_load(Path(protocol.source).read_text())["system"]["window"]
    codes = protocol.system_commands
    checked = 0
    for (_, frame), record, shown in zip(frames, records, packets, strict=False):
        if record.get("problem") == "length" or record["header"]["syscmd_code_name"] not in codes:
            continue
        name = record["header"]["syscmd_code_name"]
        parts = layout.get(name, {})
        part = (
            "answer"
            if (record["header"]["syscmd_ack"] and "answer" in parts) or "request" not in parts
            else "request"
        )
        at = protocol.system_data_offset
        for field, spec in parts.get(part, {}).items():
            kind = spec if isinstance(spec, str) else spec["type"]
            base, _, count = kind.partition("[")
            width = {"u8": 1, "u16": 2, "u32": 4, "u64": 8, "str": 1}[base]
            n = int(count[:-1]) if count else 1
            raw = frame[at : at + width * n]
            at += width * n
            got = shown[f"tokenring.system.{name}.{part}.{field}"]
            if base == "str":
                assert got == raw.split(b"\0", 1)[0].decode("ascii", "replace"), (name, field)
            else:
                values = list(struct.unpack("<" + {1: "B", 2: "H", 4: "I", 8: "Q"}[width] * n, raw))
                assert same(values if count else values[0], got), (name, field, values, got)
            checked += 1
    assert checked > 200
    assert {r["header"]["syscmd_code_name"] for r in records if "header" in r} >= set(codes)


# --------------------------------------------------------------------------------------------
# bad input


def one_line(result: subprocess.CompletedProcess, *words: str) -> None:
    assert result.returncode == 2, (result.returncode, result.stdout[-500:], result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    for word in words:
        assert word in lines[0], (word, lines[0])
    assert result.stdout == "", result.stdout[:500]


@pytest.mark.slow
def test_a_capture_that_is_not_one_or_is_cut_short_is_one_line_and_exit_2(tmp_path: Path) -> None:
    good = tmp_path / "good.pcapng"
    write_capture(good, random_frames(20, seed=1))
    data = good.read_bytes()
    text = tmp_path / "notes.pcapng"
    text.write_text("not a capture\n")
    cut = tmp_path / "cut.pcapng"
    cut.write_bytes(data[: len(data) - 300])
    torn = tmp_path / "torn.pcapng"
    torn.write_bytes(data[:-4] + b"\xff\xff\xff\xff")  # the last block's trailing length
    pcap = tmp_path / "classic.pcapng"
    pcap.write_bytes(bytes.fromhex("d4c3b2a1020004000000000000000000ffff000081000000"))
    empty = tmp_path / "empty.pcapng"
    empty.write_bytes(b"")
    one_line(run_tokenring("sniff", "--read", str(text)), str(text), "not a pcapng file")
    one_line(run_tokenring("sniff", "--read", str(cut)), str(cut), "cut short")
    one_line(run_tokenring("sniff", "--read", str(torn)), str(torn), "lengths differ")
    one_line(run_tokenring("sniff", "--read", str(pcap)), str(pcap), "pcap file, not pcapng")
    one_line(run_tokenring("sniff", "--read", str(empty)), str(empty), "not a pcapng file")
    one_line(run_tokenring("sniff", "--read", str(tmp_path / "missing.pcapng")), "missing.pcapng")
    # a pcapng without tokenring's packets (only its section header and an Ethernet interface)
    other = tmp_path / "other.pcapng"
    section = int.from_bytes(data[4:8], "little")
    other.write_bytes(data[:section] + bytes.fromhex("0100000014000000010000000000000014000000"))
    one_line(run_tokenring("sniff", "--read", str(other)), str(other), "no frames")
    # the writers: a classic .pcap is not written, an existing file not replaced without --force
    one_line(run_tokenring("sniff", "--write", str(tmp_path / "x.pcap"), "-n", "1"), "--write", ".pcapng")
    one_line(
        run_tokenring("record", "--pcap", str(tmp_path / "x.pcap"), "--duration", "1"), "--pcap", ".pcapng"
    )
    one_line(run_tokenring("record", "--duration", "1"), "FILE.mcap", "--pcap")
    one_line(
        run_tokenring("watch", "--pcap", str(tmp_path / "x.pcap"), "--duration", "1"), "--pcap", ".pcapng"
    )
    # up refuses an existing capture before anything starts, and keeps it
    one_line(run_tokenring("up", "--no-world", "--pcap", str(good), "--duration", "1"), "--pcap", "exists")
    one_line(
        run_tokenring("up", "--no-world", "--record", str(good), "--pcap", str(good), "--force"), "--pcap"
    )
    before = good.read_bytes()
    one_line(
        run_tokenring("record", str(good), "--pcap", str(good), "--duration", "1", "--force"),
        "--pcap",
        "FILE",
    )
    assert good.read_bytes() == before


def test_a_cut_or_damaged_capture_is_a_clean_error_or_frames() -> None:
    """Every cut and many damaged copies of a real capture: :class:`UsageError` in one line, or
    frames (a byte changed inside a frame is still a frame)."""
    import tempfile

    from tokenring.errors import UsageError
    from tokenring.observe.pcapng import open_pcapng

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "seed.pcapng"
        write_capture(path, random_frames(3, seed=2))
        seed = path.read_bytes()

        def check(data: bytes) -> None:
            path.write_bytes(data)
            try:
                capture = open_pcapng(path)
                frames = list(capture)
                assert len(frames) == capture.frames
            except UsageError as exc:
                assert str(exc).strip() and "\n" not in str(exc).strip(), str(exc)

        for end in range(len(seed)):
            check(seed[:end])

        @settings(max_examples=int(os.environ.get("TOKENRING_FUZZ_EXAMPLES", "60")), deadline=None,
                  suppress_health_check=[HealthCheck.too_slow])  # fmt: skip
        @given(
            changes=st.lists(
                st.tuples(st.integers(0, len(seed) - 1), st.integers(0, 255)), min_size=1, max_size=8
            )
        )
        def damaged(changes: list[tuple[int, int]]) -> None:
            data = bytearray(seed)
            for at, value in changes:
                data[at] = value
            check(bytes(data))

        damaged()
