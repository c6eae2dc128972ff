"""Captures Wireshark opens: every frame of the wire as an ARCNET packet in a pcapng file
(``sniff --write FILE.pcapng``, ``record --pcap FILE.pcapng``), and such a file read back
(``sniff --read FILE.pcapng``).

The link type is libpcap's ``DLT_ARCNET_LINUX`` (129): each packet starts with the header the
Linux arcnet driver hands a capture (``struct arc_linux_header`` of libpcap and tcpdump), which
Wireshark's own ARCNET dissector shows::

    byte 0     source ID          the frame's SID (its byte ``token.header.sid``)
    byte 1     destination ID     the frame's DID (``token.header.did``)
    bytes 2-3  offset             the frame's own bytes 2 and 3 (``long_marker``, ``size_marker``:
                                  the COM20020 buffer's count bytes, 0 and 4 for a 512-byte packet)
    byte 4     protocol ID        :data:`ARCNET_PROTOCOL_ID`
    byte 5     split flag         0 (never fragmented)
    bytes 6-7  sequence           0 (big-endian)

followed by the whole frame as it travelled (514 bytes: the token and its CRC; a frame of another
length as it was). A protocol ID other than RFC 1051's IP/ARP (240, 241), 878.1's diagnose (128)
and BACnet (205) is followed by the split flag and the sequence in Wireshark's and tcpdump's
reading of the header (RFC 1201's soft header), hence the eight bytes. Wireshark hands the bytes
after them to whatever its ``arcnet.protocol_id`` dissector table holds for that ID: the Lua
dissector ``tokenring dissector`` generates registers itself there
(:mod:`tokenring.observe.dissector`).

Every Zenoh key frames came on gets an interface of its own, named by the key
(``tokenring/<ring>/token/<DID>``, described as the frames to that node): the receiver's ID as the
key said it, even for a frame whose DID byte a corrupted bit changed, and a display filter on
``frame.interface_name`` picks the frames one node received. Time stamps are the wall clock (ns
since the epoch) the tap saw each frame at, kept to the nanosecond (the interfaces'
``if_tsresol`` is 9). The section header names the tool, the ring and protocol.yaml's SHA-256.

The file is written with dpkt's pcapng blocks (dpkt reads the wire tap's pcap already; a frame's
block as dpkt's own fast path packs it, 6 us a frame) as ``FILE.part``, renamed to ``FILE`` when
it is closed: ``FILE`` is always whole. Blocks are written out at least every second, so a tap
killed outright leaves ``FILE.part`` readable up to then; a full disk ends the capture at its
last whole block, kept as ``FILE`` (see :class:`PcapngWriter`).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import struct
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from tokenring.contract import keys
from tokenring.contract.protocol import Protocol
from tokenring.errors import UsageError
from tokenring.observe.feed import FeedSource, RawSample
from tokenring.observe.recording import _WholeRecords, drop_part, part_path, publish_part, tokenring_version

#: libpcap's link type ``LINKTYPE_ARCNET_LINUX`` / ``DLT_ARCNET_LINUX``
LINKTYPE_ARCNET_LINUX = 129
#: the ARCNET protocol ID (system code) of a token frame: 0x54, "T". Not one Wireshark, libpcap,
#: tcpdump or the Linux and BSD arcnet drivers assign (0, 1, 8, 0x80, 0xC4, 0xCD, 0xD4-0xD6,
#: 0xDD, 0xE8, 0xEC, 0xF0, 0xF1, 0xF3, 0xF7, 0xFA, 0xFB); the generated dissector registers for it
ARCNET_PROTOCOL_ID = 0x54
#: bytes of the ARCNET header before the frame
ARCNET_HEADER_SIZE = 8
#: pcapng's ``if_tsresol``: time stamps in 10^-9 s
TSRESOL_NS = 9
#: blocks are written out at least this often (what a tap killed outright can lose)
FLUSH_INTERVAL_S = 1.0
#: and whenever this many bytes wait
FLUSH_BYTES = 1 << 20
PCAPNG_MAGIC = b"\x0a\x0d\x0d\x0a"
#: the first bytes of a classic pcap file (either byte order, micro- or nanosecond stamps)
PCAP_MAGICS = frozenset({b"\xd4\xc3\xb2\xa1", b"\xa1\xb2\xc3\xd4", b"\x4d\x3c\xb2\xa1", b"\xa1\xb2\x3c\x4d"})

# pcapng's block types and option codes (the IETF's draft-ietf-opsawg-pcapng)
_SHB, _IDB, _EPB, _SPB = 0x0A0D0D0A, 0x00000001, 0x00000006, 0x00000003
_OPT_COMMENT, _OPT_SHB_USERAPPL = 1, 4
_OPT_IF_NAME, _OPT_IF_DESCRIPTION, _OPT_IF_TSRESOL, _OPT_IF_TSOFFSET = 2, 3, 9, 14
_SHA_RE = re.compile(r"protocol\.yaml sha256 ([0-9a-f]{64})")


def is_pcapng_path(path: str | os.PathLike[str]) -> bool:
    """Whether a file named so is written as pcapng (by its extension, as ``--write`` chooses)."""
    return str(path).lower().endswith(".pcapng")


def arcnet_header(frame: bytes, did: int | None, protocol: Protocol) -> bytes:
    """The Linux ARCNET header of ``frame`` (see the module's table); a byte the frame is too
    short to hold is 0, the destination then the key's ``did``."""
    header = protocol.header

    def byte(offset: int, default: int) -> int:
        return frame[offset] if offset < len(frame) else default

    return bytes(
        (
            byte(header.sid, 0),
            byte(header.did, did or 0),
            byte(header.long_marker, 0),
            byte(header.size_marker, 0),
            ARCNET_PROTOCOL_ID,
            0,  # split flag: not fragmented
            0,  # sequence, big-endian
            0,
        )
    )


def protocol_sha256(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


class TokenFrames(FeedSource):
    """A feed source of the token's frames only (``record --pcap``): the raw samples of
    ``token/*`` reach the feed's raw sinks; no topic message is made of them."""

    def keys(self, ring: str) -> list[str]:
        return [keys.token(ring, "*")]


# --------------------------------------------------------------------------------------------
# writing


class PcapngWriter:
    """A pcapng capture being written: :meth:`on_raw` takes a frame (a raw sink of
    :class:`tokenring.observe.feed.Feed`, or ``sniff``'s loop), :meth:`tick` writes out what
    waited long enough, :meth:`close` finishes it as ``FILE``, :meth:`discard` leaves no file.

    Thread-safe. A write that fails (a full disk) ends the capture at once: :attr:`failure` says
    so in one line naming the file, later frames are dropped, and what was written whole becomes
    ``FILE`` (a live ring's frames cannot be had again); none written whole: no file at all,
    ``FILE`` as it was."""

    def __init__(
        self,
        path: str | Path,
        *,
        ring: str,
        protocol: Protocol,
        protocol_text: str | None = None,
        flush_interval_s: float = FLUSH_INTERVAL_S,
    ) -> None:
        from dpkt import pcapng

        self._blocks = pcapng
        self.path = Path(path)
        self.part = part_path(self.path)
        self.ring = ring
        self.protocol = protocol
        self.flush_interval_s = flush_interval_s
        self.frames = 0  # frames taken
        self.frames_kept = 0  # frames in the file whole
        #: why the capture ended early (one line naming the file), or None
        self.failure: str | None = None
        self._interfaces: dict[str, int] = {}
        header = protocol.header
        self._header_offsets = (header.sid, header.did, header.long_marker, header.size_marker)
        self._header_reach = max(self._header_offsets)  # a frame longer than this holds them all
        epb = pcapng.EnhancedPacketBlockLE()
        self._pack_epb = epb._pack_hdr
        self._epb_size = epb.__hdr_len__  # the block's fixed fields, both lengths included
        #: blocks not written yet, each with the frames it holds (0 or 1), and their bytes
        self._pending: list[tuple[bytes, int]] = []
        self._pending_bytes = 0
        self._lock = threading.Lock()
        self._closed = False
        self._last_flush = time.monotonic()
        about = f"tokenring capture of ring {ring!r}"
        if protocol_text is not None:
            about += f"; protocol.yaml sha256 {protocol_sha256(protocol_text)}"
        shb = pcapng.SectionHeaderBlockLE(
            opts=[
                self._option(_OPT_COMMENT, about.encode()),
                self._option(_OPT_SHB_USERAPPL, f"tokenring {tokenring_version()}".encode()),
                self._option(0, b""),
            ]
        )
        try:
            self._file = _WholeRecords(self.part)
        except OSError as exc:
            raise UsageError(f"{self.path}: cannot write the capture: {exc.strerror or exc}") from None
        try:
            self._file.write(bytes(shb))
        except OSError as exc:
            self._file.close()
            with contextlib.suppress(OSError):
                self.part.unlink()
            raise UsageError(f"{self.path}: cannot write the capture: {exc.strerror or exc}") from None

    def _option(self, code: int, data: bytes) -> Any:
        return self._blocks.PcapngOptionLE(code=code, data=data)

    def _interface(self, key: str) -> int:
        """The interface of ``key``; its description block goes out before its first frame."""
        index = self._interfaces.get(key)
        if index is None:
            index = self._interfaces[key] = len(self._interfaces)
            did = keys.id_from_key(key)
            about = f"frames to node {did} of ring {self.ring!r}" if did is not None else "frames"
            idb = self._blocks.InterfaceDescriptionBlockLE(
                linktype=LINKTYPE_ARCNET_LINUX,
                snaplen=0,  # no limit
                opts=[
                    self._option(_OPT_IF_NAME, key.encode()),
                    self._option(_OPT_IF_DESCRIPTION, about.encode()),
                    self._option(_OPT_IF_TSRESOL, bytes((TSRESOL_NS,))),
                    self._option(0, b""),
                ],
            )
            self._add(bytes(idb), 0)
        return index

    def on_raw(self, raw: RawSample) -> None:
        """Add one frame as it came on ``raw.key`` at ``raw.time_ns``."""
        frame = raw.payload
        if len(frame) > self._header_reach:
            sid, did, low, high = self._header_offsets
            head = bytes((frame[sid], frame[did], frame[low], frame[high], ARCNET_PROTOCOL_ID, 0, 0, 0))
        else:
            head = arcnet_header(frame, keys.id_from_key(raw.key), self.protocol)
        # the enhanced packet block as dpkt's own fast writer (Writer.writepkts) builds it: its
        # header struct packed once per frame, the packet padded to 32 bits, no options
        size = ARCNET_HEADER_SIZE + len(frame)
        padding = -size % 4
        total = self._epb_size + size + padding
        stamp = raw.time_ns
        with self._lock:
            if self._closed:
                return
            interface = self._interface(raw.key)
            header = self._pack_epb(
                _EPB, total, interface, stamp >> 32, stamp & 0xFFFFFFFF, size, size, total
            )
            self._add(b"".join((header[:-4], head, frame, b"\0" * padding, header[-4:])), 1)
            self.frames += 1
            if self._pending_bytes >= FLUSH_BYTES:
                self._flush()
            else:
                self._maybe_flush()

    def _maybe_flush(self) -> None:
        if time.monotonic() - self._last_flush >= self.flush_interval_s:
            self._flush()

    def _add(self, block: bytes, frames: int) -> None:
        self._pending.append((block, frames))
        self._pending_bytes += len(block)

    def _flush(self) -> None:
        """Write out what waits (the lock held), in one write; if that fails (a full disk), block
        by block, so that the file keeps every block that fits. A failure ends the capture."""
        self._last_flush = time.monotonic()
        if not self._pending:
            return
        try:
            self._file.write(b"".join(block for block, _ in self._pending))
            self.frames_kept += sum(frames for _, frames in self._pending)
        except OSError:
            try:  # (the failed write was cut off the file again; write on from its end)
                os.lseek(self._file.fd, self._file.size, os.SEEK_SET)
            except OSError as exc:
                self._fail(exc)
                return
            for block, frames in self._pending:
                try:
                    self._file.write(block)
                except OSError as exc:
                    self._fail(exc)
                    return
                self.frames_kept += frames
        self._pending.clear()
        self._pending_bytes = 0

    def _fail(self, exc: OSError) -> None:
        self._closed = True
        self._pending.clear()
        self._file.close()
        if self.frames_kept:
            os.replace(self.part, self.path)
            kept = f"the capture ends at its last whole block ({self.frames_kept} frames)"
        else:
            with contextlib.suppress(OSError):
                self.part.unlink()
            kept = "nothing was kept" + (" (the file there is as it was)" if self.path.exists() else "")
        self.failure = f"{self.path}: cannot write the capture: {exc.strerror or exc}; {kept}"

    def tick(self) -> None:
        """Write out blocks that waited :attr:`flush_interval_s` (call it now and then)."""
        with self._lock:
            if not self._closed:
                self._maybe_flush()

    def close(self) -> Path:
        """Write out the rest, sync, and move the file to its final name (a capture that failed:
        see :attr:`failure`; what it kept is already there)."""
        with self._lock:
            if self._closed:
                return self.path
            self._flush()
            if self._closed:  # the last write failed
                return self.path
            try:
                publish_part(self._file, self.part, self.path)
            except OSError as exc:
                self._fail(exc)
                return self.path
            self._closed = True
        return self.path

    def discard(self) -> None:
        """Close without a capture: ``FILE.part`` is removed, ``FILE`` left as it was."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            drop_part(self._file, self.part)


# --------------------------------------------------------------------------------------------
# reading


@dataclass(frozen=True)
class CapturedFrame:
    """One frame of a capture: when it was seen, on which key (the interface's name, when it
    names a token key), the receiver's ID (the key's, else the ARCNET header's destination) and
    the frame's bytes after the ARCNET header."""

    time_ns: int
    key: str | None
    did: int | None
    frame: bytes


@dataclass
class Interface:
    linktype: int
    name: str | None
    tsresol: int = 6
    tsoffset_s: int = 0

    def time_ns(self, stamp: int) -> int:
        """A packet's time stamp in ns since the epoch."""
        if self.tsresol & 0x80:
            ns = (stamp * 10**9) >> (self.tsresol & 0x7F)
        elif self.tsresol <= 9:
            ns = stamp * 10 ** (9 - self.tsresol)
        else:
            ns = stamp // 10 ** (self.tsresol - 9)
        return ns + self.tsoffset_s * 10**9


@dataclass
class PcapngCapture:
    """A pcapng file opened for reading and checked whole (:func:`open_pcapng`)."""

    path: Path
    #: frames (ARCNET packets of :data:`ARCNET_PROTOCOL_ID`) and other packets
    frames: int = 0
    others: int = 0
    comments: list[str] = field(default_factory=list)

    @property
    def protocol_sha256(self) -> str | None:
        """protocol.yaml's SHA-256 the section header names (a tokenring capture), or None."""
        for comment in self.comments:
            match = _SHA_RE.search(comment)
            if match:
                return match.group(1)
        return None

    def __iter__(self) -> Iterator[CapturedFrame]:
        """The frames, in the file's order."""
        with open(self.path, "rb") as stream:
            yield from _frames(stream, self.path, self)


def _damaged(path: Path, problem: str) -> UsageError:
    return UsageError(f"{path}: not a readable pcapng file ({problem})")


def open_pcapng(path: str | Path) -> PcapngCapture:
    """Open and check a pcapng file block by block, to its end; :class:`UsageError` (one line)
    if it is not one, is cut short or is damaged anywhere."""
    file = Path(path)
    capture = PcapngCapture(file)
    try:
        with open(file, "rb") as stream:
            if stream.read(4) != PCAPNG_MAGIC:
                raise UsageError(f"{file}: not a pcapng file (it does not start with a section header block)")
            stream.seek(0)
            for _ in _frames(stream, file, capture, count=True):
                pass
    except OSError as exc:
        raise UsageError(f"{file}: cannot read: {exc.strerror or exc}") from None
    return capture


def _options(body: bytes, order: str) -> list[tuple[int, bytes]]:
    """A block's options (code, value) from its options area, up to ``opt_endofopt``."""
    out = []
    at = 0
    while at + 4 <= len(body):
        code, length = struct.unpack_from(order + "HH", body, at)
        if code == 0:
            break
        value = body[at + 4 : at + 4 + length]
        if len(value) != length:
            raise ValueError(f"option {code} runs past its block")
        out.append((code, value))
        at += 4 + (length + 3) // 4 * 4
    return out


def _frames(
    stream: IO[bytes], path: Path, capture: PcapngCapture, *, count: bool = False
) -> Iterator[CapturedFrame]:
    """Walk the blocks; yield the frames (``count``: also count them and keep the comments).

    The block framing (type, total length, its copy at the end) is read here; the blocks' own
    layouts through dpkt's pcapng classes, which know both byte orders."""
    from dpkt import pcapng

    order = "<"
    interfaces: list[Interface] = []
    at = 0
    size = os.fstat(stream.fileno()).st_size
    while True:
        head = stream.read(8)
        if not head:
            return
        if len(head) < 8:
            raise _damaged(path, f"cut short at byte {at}: {len(head)} bytes of a block header")
        if head[:4] == PCAPNG_MAGIC:  # a section header: its byte-order magic says the order
            bom = stream.read(4)
            if len(bom) < 4:
                raise _damaged(path, f"cut short at byte {at + 8 + len(bom)}: a section header")
            if bom == b"\x4d\x3c\x2b\x1a":
                order = "<"
            elif bom == b"\x1a\x2b\x3c\x4d":
                order = ">"
            else:
                raise _damaged(path, f"byte {at}: a section header without the byte-order magic")
            stream.seek(-4, os.SEEK_CUR)
            interfaces = []
        kind, length = struct.unpack(order + "II", head)
        if length < 12 or length % 4:
            raise _damaged(path, f"byte {at}: a block of {length} bytes")
        if at + length > size:  # (never read what is not there: a length may be 4 GB)
            raise _damaged(path, f"cut short at byte {size}: a block of {length} bytes at byte {at}")
        body = stream.read(length - 8)
        if len(body) < length - 8:
            raise _damaged(
                path, f"cut short at byte {at + 8 + len(body)}: a block of {length} bytes at byte {at}"
            )
        if struct.unpack(order + "I", body[-4:])[0] != length:
            raise _damaged(path, f"byte {at}: the block's two lengths differ")
        block = head + body
        le = order == "<"
        try:
            if kind == _SHB:
                shb = (pcapng.SectionHeaderBlockLE if le else pcapng.SectionHeaderBlock)(block)
                if shb.v_major != 1:
                    raise _damaged(path, f"pcapng version {shb.v_major}.{shb.v_minor}")
                if count:
                    capture.comments += [
                        v.decode("utf-8", "replace")
                        for c, v in _options(block[24:-4], order)
                        if c == _OPT_COMMENT
                    ]
            elif kind == _IDB:
                idb = (pcapng.InterfaceDescriptionBlockLE if le else pcapng.InterfaceDescriptionBlock)(block)
                interface = Interface(idb.linktype, None)
                for code, value in _options(block[16:-4], order):
                    if code == _OPT_IF_NAME:
                        interface.name = value.decode("utf-8", "replace")
                    elif code == _OPT_IF_TSRESOL and value:
                        interface.tsresol = value[0]
                    elif code == _OPT_IF_TSOFFSET and len(value) == 8:
                        interface.tsoffset_s = struct.unpack(order + "q", value)[0]
                interfaces.append(interface)
            elif kind == _EPB:
                epb = (pcapng.EnhancedPacketBlockLE if le else pcapng.EnhancedPacketBlock)(block)
                if epb.iface_id >= len(interfaces):
                    raise _damaged(path, f"byte {at}: a packet on interface {epb.iface_id}, never described")
                interface = interfaces[epb.iface_id]
                found = _frame(interface, (epb.ts_high << 32) | epb.ts_low, bytes(epb.pkt_data))
                if count:
                    capture.frames += found is not None
                    capture.others += found is None
                if found is not None:
                    yield found
            elif kind == _SPB:
                capture.others += count  # no interface, no time: not a frame we can place
        except UsageError:
            raise
        except Exception as exc:  # dpkt's unpack errors, struct errors, a bad option
            raise _damaged(
                path, f"byte {at}: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}"
            ) from None
        at += length


def _frame(interface: Interface, stamp: int, packet: bytes) -> CapturedFrame | None:
    """The token frame in one packet, or None (another link type, another protocol ID)."""
    if interface.linktype != LINKTYPE_ARCNET_LINUX or len(packet) < ARCNET_HEADER_SIZE:
        return None
    if packet[4] != ARCNET_PROTOCOL_ID:
        return None
    key = interface.name
    did: int | None
    if key is not None and key.startswith(f"{keys.PREFIX}/") and "/token/" in key:
        did = keys.id_from_key(key)
    else:
        key, did = None, packet[1]
    return CapturedFrame(interface.time_ns(stamp), key, did, packet[ARCNET_HEADER_SIZE:])
