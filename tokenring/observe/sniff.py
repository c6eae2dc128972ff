"""``tokenring sniff``: a read-only tap decoding every frame on the wire with protocol.yaml.

Like ``candump`` + ``cantools decode``: one line per frame (header, CRC verdict, the channels
that carry something), or with ``--json`` one object per frame. It never writes to the ring.
"""

from __future__ import annotations

import time
from typing import Any

from tokenring.contract.frame import frame_problem
from tokenring.contract.protocol import Protocol


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
    header: dict[str, Any] = {name: frame[offset] for name, offset in protocol.header.offsets.items()}
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
