"""A node's data channel as its own frames carry it, read off the wire with PyYAML and struct:
the ring tests' judge of a sensor node, sharing nothing with tokenring's token code."""

from __future__ import annotations

import struct
import threading
from typing import Any

import yaml

from tests.support.processes import REPO
from tests.support.ringjudge import Header

FORMATS = {"u8": "B", "i8": "b", "u16": "H", "i16": "h", "u32": "I", "i32": "i"}


class DataChannelReader:
    """``<node>.data`` from the frames node ``node`` sends (SID: one publisher, so in the order
    sent; frames of different hops may reach the tap out of order), each change once."""

    def __init__(self, session: Any, ring: str, node: str) -> None:
        spec = yaml.safe_load((REPO / "protocol.yaml").read_text())["nodes"][node]
        fields = spec["data"]["fields"]
        self.header = Header.from_protocol()
        self.node_id = spec["id"]
        self.names = list(fields)
        types = [f if isinstance(f, str) else f["type"] for f in fields.values()]
        self.format = "<" + "".join(FORMATS[t] for t in types)
        self.address = spec["data"]["address"]
        self.seen: list[dict[str, int]] = []
        self.lock = threading.Lock()
        self.sub = session.declare_subscriber(f"tokenring/{ring}/token/*", self._on)

    def _on(self, sample: Any) -> None:
        frame = sample.payload.to_bytes()
        if not self.header.valid(frame) or frame[0] != self.node_id:
            return
        data = dict(zip(self.names, struct.unpack_from(self.format, frame, self.address), strict=True))
        with self.lock:
            if not self.seen or self.seen[-1] != data:
                self.seen.append(data)

    def values(self) -> list[dict[str, int]]:
        with self.lock:
            return list(self.seen)

    def newest(self) -> dict[str, int] | None:
        with self.lock:
            return self.seen[-1] if self.seen else None

    def close(self) -> None:
        self.sub.undeclare()
