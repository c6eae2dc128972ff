"""``tokenring sniff``: a read-only tap decoding every frame on the wire with protocol.yaml.

Like ``candump`` + ``cantools decode``: one line per frame (header, CRC verdict, the channels
that carry something), or with ``--json`` one object per frame. It never writes to the ring.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

import zenoh

from tokenring import keys
from tokenring.cliutil import add_ring_options, tap_session
from tokenring.errors import UsageError
from tokenring.frame import frame_problem
from tokenring.protocol import Protocol, load_protocol


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sniff",
        help="decode every frame on the wire (read-only)",
        description="Decode every token frame of a running ring with protocol.yaml.",
    )
    p.add_argument("--json", action="store_true", help="one JSON object per frame")
    p.add_argument("-n", "--count", type=int, metavar="N", help="stop after N frames")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    p.add_argument("--to", type=int, metavar="ID", help="only frames addressed to node ID")
    p.add_argument(
        "--channels",
        metavar="LIST",
        help="comma-separated channels to decode (e.g. sonar.data,motor.command); default: all non-empty",
    )
    p.add_argument("--header-only", action="store_true", help="decode only the header")
    add_ring_options(p)


def decode_frame(
    frame: bytes,
    did_key: int | None,
    protocol: Protocol,
    channels: list[str] | None,
    header_only: bool,
) -> dict[str, Any]:
    """A frame as a dict: ``ok``/``problem``, header, CRC and decoded channels."""
    out: dict[str, Any] = {"t": time.time(), "key_did": did_key, "length": len(frame)}
    problem = frame_problem(frame, protocol)
    out["crc_ok"] = problem not in ("crc", "length")
    out["ok"] = problem is None
    if problem:
        out["problem"] = problem
    if len(frame) != protocol.frame_size:
        return out
    header = {name: frame[offset] for name, offset in protocol.header.offsets.items()}
    header["syscmd_code_name"] = protocol.system_command_name(header["syscmd_code"])
    out["header"] = header
    size = protocol.token_size
    out["crc"] = frame[size] | (frame[size + 1] << 8)
    if header_only:
        return out
    decoded: dict[str, Any] = {}
    for node in protocol.nodes.values():
        for ch in (node.command, node.data):
            if channels is not None and ch.name not in channels:
                continue
            raw = frame[ch.address : ch.end]
            if channels is None and not any(raw):
                continue
            if ch.kind == "command":
                decoded[ch.name] = ch.decode_command(frame)  # type: ignore[attr-defined]
            else:
                decoded[ch.name] = ch.decode(frame)
    out["channels"] = decoded
    return out


def format_line(record: dict[str, Any]) -> str:
    if "header" not in record:
        return f"<{record['length']} bytes to {record['key_did']}: {record.get('problem')}>"
    h = record["header"]
    parts = [
        f"#{h['counter']:3d}{' (repeat)' if record.get('retransmission') else ''}",
        f"{h['sid']:3d}->{h['did']:<3d}",
        f"epoch {h['epoch']}/{h['epoch_origin']}",
        f"crc {record['crc']:04X}{'' if record['crc_ok'] else ' BAD'}",
    ]
    if h["syscmd_issuer"]:
        parts.append(
            f"sys {h['syscmd_code_name']} {h['syscmd_issuer']}->{h['syscmd_target']} ack={h['syscmd_ack']}"
        )
    for name, fields in record.get("channels", {}).items():
        if "command" in fields:
            args = ",".join(f"{k}={v}" for k, v in fields["args"].items())
            parts.append(
                f"{name}:{fields['command']}({args}) from {fields['sender']} state {fields['state']}"
            )
        else:
            text = ",".join(f"{k}={v}" for k, v in fields.items() if v not in (0, [0] * 8, ""))
            parts.append(f"{name}{{{text}}}")
    return "  ".join(parts)


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
    last_crc: dict[int | None, int] = {}
    deadline = None if args.duration is None else time.monotonic() + args.duration
    with tap_session(args) as session:
        subscriber = session.declare_subscriber(key, zenoh.handlers.FifoChannel(8192))
        try:
            while True:
                if deadline is not None and time.monotonic() >= deadline:
                    break
                sample = subscriber.try_recv()
                if sample is None:
                    time.sleep(0.002)
                    continue
                frame = sample.payload.to_bytes()
                did = keys.id_from_key(str(sample.key_expr))
                record = decode_frame(frame, did, protocol, channels, args.header_only)
                # a pass repeated because its acknowledgement was late: same bytes, same receiver
                record["retransmission"] = "crc" in record and last_crc.get(did) == record["crc"]
                if "crc" in record:
                    last_crc[did] = record["crc"]
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
