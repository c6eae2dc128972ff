"""The map module's storage: line vectors as the seed kept them — 4 × int16 centimetres, 8 bytes each.

The seed's map computer had 32 KB for vectors: 4096 of them. :class:`VectorStore` holds exactly
that many in one ``(4096, 4)`` int16 array; a full store refuses new vectors (nothing is
overwritten). Helpers convert between the wire (cm) and the programs' millimetres.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Iterator

import numpy as np

#: the seed's capacity: 32 KB of 8-byte vectors
CAPACITY = 4096
#: one vector on the wire and in memory: x1, y1, x2, y2 as little-endian int16 centimetres
VECTOR_FORMAT = struct.Struct("<4h")
INT16_MIN, INT16_MAX = -32768, 32767


def mm_to_cm(value_mm: float) -> int:
    """Round millimetres to the wire's whole centimetres, clamped to int16 (±327 m)."""
    return max(INT16_MIN, min(INT16_MAX, round(value_mm / 10.0)))


def vector_to_wire(x1_mm: float, y1_mm: float, x2_mm: float, y2_mm: float) -> dict[str, int]:
    """A vector in mm as the VECTOR command's arguments (cm)."""
    return {"x1": mm_to_cm(x1_mm), "y1": mm_to_cm(y1_mm), "x2": mm_to_cm(x2_mm), "y2": mm_to_cm(y2_mm)}


def wire_to_vector_mm(args: dict[str, int]) -> tuple[float, float, float, float]:
    """VECTOR arguments (cm) as a vector in mm."""
    return (args["x1"] * 10.0, args["y1"] * 10.0, args["x2"] * 10.0, args["y2"] * 10.0)


class MapFull(Exception):
    """The store holds :data:`CAPACITY` vectors already."""


class VectorStore:
    """A fixed-capacity list of int16-centimetre vectors (the seed's linked list, made flat)."""

    def __init__(self, capacity: int = CAPACITY) -> None:
        self.capacity = capacity
        self.data = np.zeros((capacity, 4), dtype="<i2")
        self.count = 0

    def __len__(self) -> int:
        return self.count

    @property
    def left(self) -> int:
        return self.capacity - self.count

    def add(self, x1: int, y1: int, x2: int, y2: int) -> int:
        """Store one vector (cm); returns its index. Raises :class:`MapFull` and changes nothing."""
        if self.count >= self.capacity:
            raise MapFull(f"the map holds {self.capacity} vectors already")
        self.data[self.count] = (x1, y1, x2, y2)
        self.count += 1
        return self.count - 1

    def clear(self) -> None:
        self.count = 0
        self.data[:] = 0

    def vectors(self) -> list[tuple[int, int, int, int]]:
        """A copy of the stored vectors, oldest first."""
        return [tuple(int(v) for v in row) for row in self.data[: self.count]]  # type: ignore[misc]

    def __iter__(self) -> Iterator[tuple[int, int, int, int]]:
        return iter(self.vectors())

    def to_bytes(self) -> bytes:
        """The stored vectors in the 8-byte wire format, back to back."""
        return self.data[: self.count].astype("<i2").tobytes()

    @classmethod
    def from_vectors(cls, vectors: Iterable[Iterable[int]], capacity: int = CAPACITY) -> VectorStore:
        store = cls(capacity)
        for v in vectors:
            store.add(*v)
        return store


def pack_vectors(vectors: Iterable[Iterable[int]]) -> bytes:
    """Vectors (cm) in the 8-byte format."""
    return b"".join(VECTOR_FORMAT.pack(*v) for v in vectors)


def unpack_vectors(blob: bytes) -> list[tuple[int, int, int, int]]:
    """The inverse of :func:`pack_vectors`; the blob's length must be a multiple of 8."""
    if len(blob) % VECTOR_FORMAT.size:
        raise ValueError(f"a vector blob is a multiple of {VECTOR_FORMAT.size} bytes, got {len(blob)}")
    return [tuple(v) for v in VECTOR_FORMAT.iter_unpack(blob)]  # type: ignore[misc]
