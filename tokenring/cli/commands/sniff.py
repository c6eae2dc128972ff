"""``tokenring sniff``: decode every frame on the wire (read-only); the decoding is
:mod:`tokenring.observe.sniff`'s."""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import time
from typing import TYPE_CHECKING, Any

from tokenring.cli.args import add_ring_options, node_id, positive_int, seconds, with_examples
from tokenring.errors import TransportError, UsageError

if TYPE_CHECKING:
    from collections.abc import Iterator

    from tokenring.contract.protocol import Protocol

HELP = "decode every frame on the wire (read-only), or of an MCAP or pcapng capture"

EXAMPLES = """examples:
  tokenring sniff --channels motor.data,sonar.data
  tokenring sniff --json -n 100 --to 20
  tokenring sniff --write frames.mcap --duration 30     # capture while showing
  tokenring sniff --read frames.mcap --json             # decode a capture offline
  tokenring sniff --write frames.pcapng --duration 30   # a capture Wireshark opens (ARCNET)
  tokenring dissector > tokenring.lua && wireshark -X lua_script:tokenring.lua frames.pcapng
  tokenring sniff --read frames.pcapng --channels motor.command
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sniff",
        help=HELP,
        description="Decode every token frame of a running ring with protocol.yaml; --write also "
        "captures them, to an MCAP file (raw and decoded) or, named FILE.pcapng, to a pcapng file "
        "of ARCNET packets that Wireshark and tshark open (with 'tokenring dissector' to decode "
        "the token inside; see docs/wireshark.md); --read decodes either file offline (like "
        "candump -l and cantools decode).",
        **with_examples(EXAMPLES),
    )
    p.add_argument("--json", action="store_true", help="one JSON object per frame")
    p.add_argument("-n", "--count", type=positive_int, metavar="N", help="stop after N frames")
    p.add_argument(
        "--wait",
        type=seconds,
        default=10.0,
        metavar="S",
        help="give up when no frame has come within S seconds of starting (default %(default)s)",
    )
    p.add_argument("--duration", type=seconds, metavar="S", help="stop after S seconds")
    p.add_argument("--to", type=node_id, metavar="ID", help="only frames addressed to node ID")
    p.add_argument(
        "--channels",
        metavar="LIST",
        help="comma-separated channels to decode (e.g. sonar.data,motor.command); default: all non-empty",
    )
    p.add_argument("--header-only", action="store_true", help="decode only the header")
    capture = p.add_mutually_exclusive_group()
    capture.add_argument(
        "--write",
        metavar="FILE",
        help="also capture the frames: FILE.pcapng as ARCNET packets (Wireshark, tshark), any other "
        "name as MCAP (raw and decoded)",
    )
    capture.add_argument(
        "--read",
        metavar="FILE",
        help="decode the frames of an MCAP recording or a pcapng capture instead of the wire",
    )
    p.add_argument("--force", action="store_true", help="replace an existing --write FILE")
    add_ring_options(p)


def run(args: argparse.Namespace) -> int:
    import json
    import uuid

    import zenoh

    from tokenring.cli.args import tap_session
    from tokenring.cli.output import check_option_output
    from tokenring.contract import keys
    from tokenring.contract.protocol import load_protocol
    from tokenring.observe.feed import RawSample
    from tokenring.observe.sniff import decode_frame, format_line

    if args.read:
        return read_file(args)
    if args.write:
        if args.write.lower().endswith(".pcap"):
            raise UsageError(
                f"--write {args.write}: a capture for Wireshark is written as pcapng: name it .pcapng"
            )
        check_option_output("--write", args.write, force=args.force)
    protocol = load_protocol(args.protocol)
    ring = keys.check_ring_name(args.ring)
    channels = None
    if args.channels:
        channels = [c.strip() for c in args.channels.split(",") if c.strip()]
        for name in channels:
            try:
                protocol.channel(name)
            except Exception as exc:
                raise UsageError(str(exc)) from None
    key = keys.token(ring, args.to if args.to is not None else "*")
    seen = 0
    last_frame: dict[int | None, bytes] = {}
    ended = False
    started = time.monotonic()
    deadline = None if args.duration is None else started + args.duration
    stopper = None
    if args.write:
        from tokenring.observe.recording import Stopper

        # Ctrl-C and SIGTERM end a capture between two frames: the file holds what was printed
        stopper = Stopper()
        stopper.install()
    with tap_session(args) as session:
        # opened once the session is: a refused endpoint leaves no FILE.part behind
        capture = open_capture(args, protocol, ring)
        subscriber = session.declare_subscriber(key, zenoh.handlers.FifoChannel(8192))
        # Zenoh's receiving thread hands the question on only after the frames that came before
        # it are in the channel above: `play` asks before it closes, so nothing queued towards
        # this sniff is lost
        tap_id = uuid.uuid4().hex
        drained_key = keys.tap_drained(ring, tap_id)  # the reply names this tap (play counts them)
        drained = session.declare_queryable(drained_key, lambda query: query.reply(drained_key, b""))
        # declared after the queryable: whoever sees the token can already ask it
        alive = session.liveliness().declare_token(keys.tap(ring, tap_id))
        try:
            while True:
                if deadline is not None and time.monotonic() >= deadline:
                    break
                if stopper is not None and stopper.event.is_set():
                    break
                sample = subscriber.try_recv()
                if sample is None:
                    if not seen and time.monotonic() - started > args.wait:
                        raise TransportError(
                            f"no frame on {key} within {args.wait:g} s (is the ring running, and are "
                            "--ring and --connect right?)"
                        )
                    time.sleep(0.002)
                    continue
                seen_ns = time.time_ns()  # the frame's time, in the capture and as printed
                frame = sample.payload.to_bytes()
                did = keys.id_from_key(str(sample.key_expr))
                if capture is not None:
                    capture.feed_raw(RawSample(str(sample.key_expr), seen_ns, frame))
                    if capture.recorder.failure:  # a full disk: the capture is over, and so is the sniff
                        break
                record = decode_frame(frame, did, protocol, channels, args.header_only)
                record["t"] = seen_ns / 1e9
                # a pass repeated because its acknowledgement was late: same bytes, same receiver
                # (every byte: two different passes share a CRC-16 once in 65536)
                record["retransmission"] = "crc" in record and last_frame.get(did) == frame
                if "crc" in record:
                    last_frame[did] = frame
                if args.json:
                    sys.stdout.write(json.dumps(record) + "\n")
                else:
                    sys.stdout.write(format_line(record) + "\n")
                seen += 1
                if args.count is not None and seen >= args.count:
                    break
            sys.stdout.flush()
            ended = True
        finally:
            with contextlib.suppress(zenoh.ZError):  # stopped on purpose: nothing was cut
                # blocking, not dropped: on a busy link a dropped goodbye, with the token's end
                # still delivered, reads to play as a tap cut off
                session.put(
                    keys.tap_left(ring, tap_id), b"", congestion_control=zenoh.CongestionControl.BLOCK
                )
            alive.undeclare()
            drained.undeclare()
            subscriber.undeclare()
            if capture is not None:
                capture.finish(seen, ended)
    if capture is not None and capture.recorder.failure:
        print(f"tokenring sniff: error: --write {capture.recorder.failure}", file=sys.stderr)
        return 1
    return 130 if stopper is not None and stopper.signal == signal.SIGINT else 0


class Capture:
    """``--write``: every frame raw and decoded (the feed's ring topics) into an MCAP file, or
    every frame as an ARCNET packet into a pcapng file (``source`` None)."""

    def __init__(self, recorder: Any, source: Any) -> None:
        self.recorder = recorder
        self.source = source

    def feed_raw(self, raw: Any) -> None:
        self.recorder.on_raw(raw)
        if self.source is not None:
            for message in self.source.translate(raw.key, raw.payload, raw.time_ns):
                self.recorder.on_message(message)
        self.recorder.tick()

    def finish(self, frames: int, ended: bool) -> None:
        """Finalise the file (``ended``: the run was not cut short by an error or Ctrl-C). One
        without a frame is not kept: a failed or empty run must not leave a FILE that a retry
        without ``--force`` is refused over. A capture that failed (a full disk) keeps what it
        wrote whole and is named by the caller."""
        if self.recorder.failure:
            return  # it is closed, what it kept is FILE
        if frames:
            path = self.recorder.close()
            if not self.recorder.failure:
                messages = "" if self.source is None else f", {self.recorder.messages} messages"
                print(f"{path}: {frames} frames{messages} captured", file=sys.stderr)
            return
        self.recorder.discard()
        if ended:
            print(f"{self.recorder.path}: no frame came; nothing written", file=sys.stderr)


def open_capture(args: argparse.Namespace, protocol: Protocol, ring: str) -> Capture | None:
    if not args.write:
        return None
    from pathlib import Path

    from tokenring.contract.protocol import default_protocol_path
    from tokenring.observe.feed import RingSource
    from tokenring.observe.pcapng import PcapngWriter, is_pcapng_path
    from tokenring.observe.recording import McapRecorder

    text = Path(args.protocol or default_protocol_path()).read_text(encoding="utf-8")
    if is_pcapng_path(args.write):
        return Capture(PcapngWriter(args.write, ring=ring, protocol=protocol, protocol_text=text), None)
    source = RingSource(protocol)
    recorder = McapRecorder(args.write, ring=ring, topics=source.topics(), protocol_text=text)
    return Capture(recorder, source)


def read_file(args: argparse.Namespace) -> int:
    """``--read``: the frames of an MCAP recording (in log-time order) or of a pcapng capture (in
    the file's order) decoded as live, ``t`` the time each was seen. Which it is, the file's
    first bytes say."""
    import json

    from tokenring._util.files import check_input
    from tokenring.observe.pcapng import PCAP_MAGICS, PCAPNG_MAGIC, is_pcapng_path
    from tokenring.observe.recording import MCAP_MAGIC
    from tokenring.observe.sniff import decode_frame, format_line

    # a FIFO, a device or a folder is refused before it is opened for reading (it could block)
    check_input(args.read, "capture", limit=1 << 62)
    try:
        with open(args.read, "rb") as stream:
            head = stream.read(len(MCAP_MAGIC))
    except OSError as exc:
        raise UsageError(f"{args.read}: cannot read: {exc.strerror or exc}") from None
    if head[:4] in PCAP_MAGICS:
        raise UsageError(
            f"{args.read}: a pcap file, not pcapng (editcap -F pcapng converts it, if it holds "
            "tokenring's ARCNET packets)"
        )
    if head.startswith(PCAPNG_MAGIC) or (not head.startswith(MCAP_MAGIC) and is_pcapng_path(args.read)):
        protocol, frames = read_pcapng(args)
    else:
        protocol, frames = read_mcap(args)
    channels = None
    if args.channels:
        channels = [c.strip() for c in args.channels.split(",") if c.strip()]
        for name in channels:
            try:
                protocol.channel(name)
            except Exception as exc:
                raise UsageError(str(exc)) from None
    first = None
    seen = 0
    last_frame: dict[int | None, bytes] = {}
    for time_ns, did, payload in frames:
        if args.to is not None and did != args.to:
            continue
        first = time_ns if first is None else first
        if args.duration is not None and time_ns - first > args.duration * 1e9:
            break
        record = decode_frame(payload, did, protocol, channels, args.header_only)
        record["t"] = time_ns / 1e9
        record["retransmission"] = "crc" in record and last_frame.get(did) == payload
        if "crc" in record:
            last_frame[did] = payload
        sys.stdout.write((json.dumps(record) if args.json else format_line(record)) + "\n")
        seen += 1
        if args.count is not None and seen >= args.count:
            break
    sys.stdout.flush()
    return 0


def read_mcap(args: argparse.Namespace) -> tuple[Protocol, Iterator[tuple[int, int | None, bytes]]]:
    """An MCAP recording's protocol (its own protocol.yaml unless one is named) and frames."""
    import os

    from tokenring.contract import keys
    from tokenring.contract.protocol import load_protocol, parse_protocol
    from tokenring.observe.recording import iter_raw, open_recording

    recording = open_recording(args.read)
    if args.protocol is None and not os.environ.get("TOKENRING_PROTOCOL") and recording.protocol_text:
        protocol = parse_protocol(recording.protocol_text, f"{args.read} (its protocol.yaml)")
    else:
        protocol = load_protocol(args.protocol)
    frames = [key for key in recording.raw_keys() if key.rsplit("/", 2)[-2:-1] == ["token"]]
    if args.to is not None:
        frames = [key for key in frames if keys.id_from_key(key) == args.to]
    if not frames:
        raise UsageError(f"{args.read}: no frames recorded" + (f" to node {args.to}" if args.to else ""))
    wanted = set(frames)
    return protocol, (
        (raw.time_ns, keys.id_from_key(raw.key), raw.payload)
        for raw in iter_raw(recording, None, None, None)
        if raw.key in wanted
    )


def read_pcapng(args: argparse.Namespace) -> tuple[Protocol, Iterator[tuple[int, int | None, bytes]]]:
    """A pcapng capture's frames (checked whole first), decoded with the protocol.yaml loaded;
    a capture that names another protocol.yaml's digest is said so on stderr."""
    from pathlib import Path

    from tokenring.contract.protocol import default_protocol_path, load_protocol
    from tokenring.observe.pcapng import open_pcapng, protocol_sha256

    capture = open_pcapng(args.read)
    protocol = load_protocol(args.protocol)
    if not capture.frames:
        raise UsageError(
            f"{args.read}: no frames recorded (no ARCNET packet of tokenring's protocol ID"
            + (f"; {capture.others} other packets)" if capture.others else ")")
        )
    path = Path(args.protocol or default_protocol_path())
    digest = capture.protocol_sha256
    if digest is not None and digest != protocol_sha256(path.read_text(encoding="utf-8")):
        print(
            f"tokenring sniff: note: {args.read} was captured with another protocol.yaml "
            f"(sha256 {digest[:12]}...); decoding with {path}",
            file=sys.stderr,
        )
    return protocol, ((frame.time_ns, frame.did, frame.frame) for frame in capture)
