"""The 512-byte token and its 514-byte frame (token + CRC-16/ARC, little-endian).

:class:`Token` is the friendly wrapper with header accessors used by tools and tests; the node
OS works on the same layout through raw offsets compiled from ``protocol.yaml`` for speed.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import fastcrc

from tokenring.contract.protocol import Protocol, default_protocol
from tokenring.errors import FrameError

CRC_SIZE = 2


#: CRC-16/ARC (poly 0x8005 reflected, init 0): ARCNET's own CRC; check value 0xBB3D. The C
#: function itself, not a Python wrapper: the token path calls it twice per visit, each extra
#: Python frame there costs microseconds in a process whose caches the other nodes evicted
crc16_arc: Callable[[bytes | bytearray | memoryview], int] = fastcrc.crc16.arc


def seal(frame: bytearray, token_size: int = 512) -> None:
    """Write the CRC of ``frame[:token_size]`` into the two bytes after it."""
    crc = fastcrc.crc16.arc(memoryview(frame)[:token_size])
    frame[token_size] = crc & 0xFF
    frame[token_size + 1] = crc >> 8


def frame_problem(frame: bytes, protocol: Protocol) -> str | None:
    """The name of the first check ``frame`` fails (``length``, ``crc``, ``marker``), or None."""
    size = protocol.token_size
    if len(frame) != size + CRC_SIZE:
        return "length"
    if fastcrc.crc16.arc(memoryview(frame)[:size]) != frame[size] | (frame[size + 1] << 8):
        return "crc"
    header = protocol.header
    for name, value in header.consts.items():
        if frame[header.offsets[name]] != value:
            return "marker"
    return None


class Token:
    """A token buffer with named header accessors, sized and laid out by ``protocol.yaml``."""

    __slots__ = ("buffer", "protocol")

    def __init__(self, protocol: Protocol | None = None, frame: bytes | None = None) -> None:
        self.protocol = protocol or default_protocol()
        size = self.protocol.frame_size
        if frame is None:
            self.buffer = bytearray(size)
            for name, value in self.protocol.header.consts.items():
                self.buffer[self.protocol.header.offsets[name]] = value
        else:
            if len(frame) != size:
                raise FrameError("length", f"expected {size} bytes, got {len(frame)}")
            self.buffer = bytearray(frame)

    @classmethod
    def from_frame(cls, frame: bytes, protocol: Protocol | None = None) -> Token:
        """Parse a frame from the wire; raises :class:`FrameError` if it fails a check."""
        protocol = protocol or default_protocol()
        problem = frame_problem(frame, protocol)
        if problem is not None:
            raise FrameError(problem, _explain(problem, frame, protocol))
        return cls(protocol, frame)

    def to_frame(self) -> bytes:
        """The 514-byte frame, CRC included."""
        seal(self.buffer, self.protocol.token_size)
        return bytes(self.buffer)

    def __getitem__(self, name: str) -> int:
        return self.buffer[self.protocol.header.offsets[name]]

    def __setitem__(self, name: str, value: int) -> None:
        self.buffer[self.protocol.header.offsets[name]] = value

    sid = property(lambda self: self["sid"], lambda self, v: self.__setitem__("sid", v))
    did = property(lambda self: self["did"], lambda self, v: self.__setitem__("did", v))
    counter = property(lambda self: self["counter"], lambda self, v: self.__setitem__("counter", v))
    epoch = property(lambda self: self["epoch"], lambda self, v: self.__setitem__("epoch", v))

    @property
    def crc(self) -> int:
        size = self.protocol.token_size
        return self.buffer[size] | (self.buffer[size + 1] << 8)

    def header(self) -> dict[str, int]:
        return {name: self.buffer[off] for name, off in self.protocol.header.offsets.items()}

    def decode(self) -> dict[str, Any]:
        """Header and every channel decoded with ``protocol.yaml`` (what ``sniff`` prints)."""
        protocol = self.protocol
        out: dict[str, Any] = {"header": self.header(), "crc": self.crc}
        head = out["header"]
        head["syscmd_code_name"] = protocol.system_command_name(head["syscmd_code"])
        channels: dict[str, Any] = {}
        for node in protocol.nodes.values():
            channels[node.command.name] = node.command.decode_command(self.buffer)
            channels[node.data.name] = node.data.decode(self.buffer)
        out["channels"] = channels
        return out


def _explain(problem: str, frame: bytes, protocol: Protocol) -> str:
    size = protocol.token_size
    if problem == "length":
        return f"expected {size + CRC_SIZE} bytes, got {len(frame)}"
    if problem == "crc":
        got = frame[size] | (frame[size + 1] << 8)
        return f"CRC 0x{got:04X} does not match computed 0x{crc16_arc(frame[:size]):04X}"
    return "bytes 2-3 are not the ARCNET long-packet markers 0 and 4"
