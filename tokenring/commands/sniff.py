"""``tokenring sniff``: decode every frame on the wire (read-only); the decoding is
:mod:`tokenring.sniff`'s."""

from __future__ import annotations

import argparse
import json
import sys
import time

import zenoh

from tokenring import keys
from tokenring.cliutil import add_ring_options, node_id, positive_int, seconds, tap_session
from tokenring.errors import TransportError, UsageError
from tokenring.protocol import load_protocol
from tokenring.sniff import decode_frame, format_line


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sniff",
        help="decode every frame on the wire (read-only)",
        description="Decode every token frame of a running ring with protocol.yaml.",
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
    add_ring_options(p)


def run(args: argparse.Namespace) -> int:
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
    started = time.monotonic()
    deadline = None if args.duration is None else started + args.duration
    with tap_session(args) as session:
        subscriber = session.declare_subscriber(key, zenoh.handlers.FifoChannel(8192))
        try:
            while True:
                if deadline is not None and time.monotonic() >= deadline:
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
                frame = sample.payload.to_bytes()
                did = keys.id_from_key(str(sample.key_expr))
                record = decode_frame(frame, did, protocol, channels, args.header_only)
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
        finally:
            subscriber.undeclare()
    return 0
