"""The packets lopscpp sends to the robot's LOPS module (seed 000 tables 6.1 and 6.2).

A data packet: ``'S' 'D'``, the counter (long, 4 bytes), the three distances (double[3]), X and
Y (double), ``'E'`` — 47 bytes. A message packet (lopscpp's error messages, which the robot hands
to its MessageHandler): ``'S' 'M'``, the length (one unsigned byte), the message (char[]),
``'E'``. "Die Daten werden von zwei Bytes zur Synchronisation eingerahmt, um den Verlust von
einzelnen Bytes zu Erkennen. Die Daten selbst werden binärkodiert": binary, little-endian as on the
seed's x86 PCs, unpadded. The seed does not say what stands in a field without a value; here a
distance nobody heard and the X and Y of a measurement without a position are NaN.

This module imports nothing of the world: the robot's side may read the packets with it alone.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

_DATA = struct.Struct("<cci3dddc")
DATA_SIZE = _DATA.size  # 47
START, END, DATA, MESSAGE = b"S", b"E", b"D", b"M"
MAX_MESSAGE = 255


class PacketError(ValueError):
    """Bytes that are not one whole LOPS packet."""


@dataclass(frozen=True)
class DataPacket:
    """Table 6.1: Zähler, Distanzen, X, Y. ``None`` where the packet carries NaN."""

    counter: int
    distances: tuple[float | None, float | None, float | None]
    x: float | None
    y: float | None

    @property
    def position(self) -> tuple[float, float] | None:
        """(X, Y) in mm, or None: no position this time (a receiver failed or the filter refused it)."""
        if self.x is None or self.y is None:
            return None
        return (self.x, self.y)


@dataclass(frozen=True)
class MessagePacket:
    """Table 6.2: one of lopscpp's messages."""

    text: str


Packet = DataPacket | MessagePacket


def _nan(value: float | None) -> float:
    return math.nan if value is None else float(value)


def _none(value: float) -> float | None:
    return None if math.isnan(value) else value


def pack_data(packet: DataPacket) -> bytes:
    """Table 6.1's 47 bytes; the counter wraps as the seed's 32-bit long would."""
    counter = (packet.counter + 2**31) % 2**32 - 2**31
    d = packet.distances
    return _DATA.pack(
        START, DATA, counter, _nan(d[0]), _nan(d[1]), _nan(d[2]), _nan(packet.x), _nan(packet.y), END
    )


def pack_message(packet: MessagePacket) -> bytes:
    """Table 6.2's frame around the message (Latin-1, as the seed's chars; cut to 255 bytes)."""
    body = packet.text.encode("latin-1", "replace")[:MAX_MESSAGE]
    return START + MESSAGE + bytes([len(body)]) + body + END


def pack(packet: Packet) -> bytes:
    return pack_data(packet) if isinstance(packet, DataPacket) else pack_message(packet)


def parse(data: bytes) -> Packet:
    """Exactly one packet; raises :class:`PacketError` for anything else."""
    packet, used = _parse_at(memoryview(bytes(data)), 0)
    if packet is None:
        raise PacketError(f"not a whole LOPS packet ({len(data)} bytes: {bytes(data[:8])!r}...)")
    if used != len(data):
        raise PacketError(f"{len(data) - used} bytes after the packet's 'E'")
    return packet


def _parse_at(buf: memoryview, i: int) -> tuple[Packet | None, int]:
    """The packet starting at ``buf[i]`` and the offset after it; (None, -1) if the bytes there
    cannot be one, (None, 0) if they may be the start of one still incomplete."""
    n = len(buf)
    if n - i < 2:
        return None, 0
    if buf[i : i + 1] != START:
        return None, -1
    kind = bytes(buf[i + 1 : i + 2])
    if kind == DATA:
        if n - i < DATA_SIZE:
            return None, 0
        fields = _DATA.unpack_from(buf, i)
        if fields[-1] != END:
            return None, -1
        _, _, counter, d0, d1, d2, x, y, _ = fields
        return DataPacket(counter, (_none(d0), _none(d1), _none(d2)), _none(x), _none(y)), i + DATA_SIZE
    if kind == MESSAGE:
        if n - i < 3:
            return None, 0
        length = buf[i + 2]
        end = i + 3 + length
        if n <= end:
            return None, 0
        if buf[end : end + 1] != END:
            return None, -1
        return MessagePacket(bytes(buf[i + 3 : end]).decode("latin-1")), end + 1
    return None, -1


class PacketReader:
    """The robot's side of the byte stream (the seed's TCP socket): :meth:`feed` bytes as they
    come, get back the whole packets. A frame that does not close with 'E' is a lost byte: the
    reader counts it and looks for the next 'S'."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self.resyncs = 0

    def feed(self, data: bytes) -> list[Packet]:
        self._buf += data
        out: list[Packet] = []
        i = 0
        view = memoryview(bytes(self._buf))
        while i < len(view):
            packet, after = _parse_at(view, i)
            if packet is not None:
                out.append(packet)
                i = after
            elif after == 0:
                break
            else:
                self.resyncs += 1
                nxt = bytes(view[i + 1 :]).find(START)
                i = len(view) if nxt < 0 else i + 1 + nxt
        del self._buf[:i]
        return out
