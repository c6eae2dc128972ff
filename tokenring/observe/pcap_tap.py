"""An outside tap on the wire: the token's frames as the kernel saw them on loopback's TCP,
captured by tcpdump (libpcap; the Debian package ``tcpdump``) and read back as pcap by dpkt.

On direct links (``--topology links``) the token passes from node to node on TCP links that no
router and no subscriber sees; the one vantage point outside the ring is the wire. tcpdump is
the real component for it: a kernel packet filter keeps only packets long enough to carry a
frame on the ports asked for, and each carries the kernel's own time stamp, so neither the
tap's nor the ring's scheduling moves the times it reports. Each packet's TCP payload is searched
for a frame whose CRC holds (Zenoh's framing sits before it), so what the tap reports is a token
the wire carried, not a packet of the right size. Capturing needs CAP_NET_RAW (root here);
without it, or without tcpdump, :class:`WireTapError` says so.
"""

from __future__ import annotations

import shutil
import subprocess
import threading
import time
from collections.abc import Iterable
from typing import IO

from tokenring._util.process import die_with_parent
from tokenring.contract.frame import crc16_arc
from tokenring.contract.protocol import Protocol, default_protocol
from tokenring.errors import TokenRingError
from tokenring.observe.capture import CapturedFrames

#: bytes kept of each packet: a frame with Zenoh's framing, or several messages batched with it.
#: In immediate mode the kernel's capture ring has one slot of this size per packet, and at
#: tcpdump's default (256 KiB) its 2 MiB held 8: a tap at 1400 frames a second lost half of them
SNAPLEN_BYTES = 8192
#: the kernel's capture ring (KiB): 4096 packets of slack while the reader catches up
BUFFER_KIB = 32768


class WireTapError(TokenRingError):
    """The capture could not start: no tcpdump, no right to capture, or it ended early."""


def tcpdump_path() -> str:
    """Where tcpdump is; raises :class:`WireTapError` if nowhere (a tool checks before it runs)."""
    # (Debian installs it in /usr/bin; some systems keep it in /usr/sbin, off a user's PATH)
    found = shutil.which("tcpdump") or shutil.which("tcpdump", path="/usr/sbin:/usr/bin")
    if found is None:
        raise WireTapError("the outside tap on direct links needs tcpdump (Debian package tcpdump)")
    return found


def find_frame(payload: bytes, protocol: Protocol) -> bytes | None:
    """The token frame in a TCP payload: the last ``frame_size`` bytes whose CRC holds (a put's
    payload ends Zenoh's message; an earlier position only where Zenoh batched something after
    it), or None."""
    size, token = protocol.frame_size, protocol.token_size
    for end in range(len(payload), size - 1, -1):
        frame = payload[end - size : end]
        if crc16_arc(frame[:token]) == frame[token] | (frame[token + 1] << 8):
            return frame
    return None


class WireTap(CapturedFrames):
    """Token frames on ``interface`` in TCP packets matching ``ports_filter`` (a pcap filter of
    ports, e.g. ``dst port 7447``): ``start()``, let the ring run, ``snapshot()`` any time,
    ``stop()``. ``frames`` holds ``(time, frame)`` in :func:`time.perf_counter`'s seconds, the
    clock the fault tools count from, oldest first."""

    def __init__(self, ports_filter: str, *, interface: str = "lo", protocol: Protocol | None = None) -> None:
        super().__init__()
        self.ports_filter = ports_filter
        self.interface = interface
        self.protocol = protocol or default_protocol()
        self.packets = 0  # packets captured, a frame in them or not
        #: packets the kernel captured but had to drop (tcpdump's count when it ends): a tap that
        #: lost frames says so rather than report a slower ring
        self.dropped = 0
        self._process: subprocess.Popen[bytes] | None = None
        self._listening = threading.Event()
        self._errors: list[str] = []
        self._threads: list[threading.Thread] = []
        # the kernel stamps packets on the wall clock; perf_counter = wall - offset
        self._offset = time.time() - time.perf_counter()

    @classmethod
    def into(cls, port: int, *, interface: str = "lo") -> WireTap:
        """The frames sent to ``port`` (a node's link port: the frames it receives there)."""
        return cls(f"dst port {port}", interface=interface)

    @classmethod
    def around(
        cls, link_ports: Iterable[int], relay_port: int | None = None, *, interface: str = "lo"
    ) -> WireTap:
        """Every frame between nodes: on each link port either way, and out of the router's port
        (``relay_port``: a frame through the router counts once, on its way to the receiver)."""
        parts = [f"port {port}" for port in sorted(set(link_ports))]
        if relay_port is not None:
            parts.append(f"src port {relay_port}")
        if not parts:
            raise ValueError("a wire tap needs at least one port")
        return cls(" or ".join(parts), interface=interface)

    def start(self, timeout_s: float = 10.0) -> None:
        """Start tcpdump and wait until it captures; raises :class:`WireTapError`."""
        command = [
            tcpdump_path(), "-i", self.interface, "-n", "-U", "-w", "-", "--immediate-mode",
            "--time-stamp-precision=nano", "-s", str(SNAPLEN_BYTES), "-B", str(BUFFER_KIB),
            f"tcp and greater {self.protocol.frame_size} and ({self.ports_filter})",
        ]  # fmt: skip
        self._process = subprocess.Popen(
            command,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            start_new_session=True,  # a Ctrl-C reaches the tool, which ends the capture itself
            preexec_fn=die_with_parent,  # and a tool killed outright takes the capture with it
        )
        self._offset = time.time() - time.perf_counter()
        assert self._process.stdout is not None and self._process.stderr is not None
        self._threads = [
            threading.Thread(target=self._read_packets, args=(self._process.stdout,), name="wiretap-out", daemon=True),
            threading.Thread(target=self._read_messages, args=(self._process.stderr,), name="wiretap-err", daemon=True),
        ]  # fmt: skip
        for thread in self._threads:
            thread.start()
        deadline = time.monotonic() + timeout_s
        while not self._listening.wait(0.05):
            if self._process.poll() is not None or time.monotonic() > deadline:
                self.stop()
                why = self._errors[-1] if self._errors else f"no capture within {timeout_s:.0f} s"
                raise WireTapError(f"tcpdump on {self.interface} ({self.ports_filter}): {why}")

    def stop(self, catch_up_s: float = 3.0) -> list[tuple[float, bytes]]:
        """End the capture; the frames, oldest first. tcpdump ends without reading what the
        kernel still holds for it, and on a loaded machine it lags hundreds of packets behind:
        so first wait (``catch_up_s`` at most) until it has passed a frame sent after this call."""
        process = self._process
        if process is not None and process.poll() is None:
            now = time.perf_counter()
            deadline = time.monotonic() + catch_up_s
            while time.monotonic() < deadline and process.poll() is None:
                with self._lock:
                    if self.frames and self.frames[-1][0] >= now:
                        break
                time.sleep(0.01)
            process.terminate()
            try:
                process.wait(5.0)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        for thread in self._threads:
            thread.join(5.0)
        return self.snapshot()

    close = stop

    def _read_packets(self, stream: IO[bytes]) -> None:
        import dpkt  # the pcap stream's reader (magic, byte order, nanosecond stamps, link type)

        try:
            reader = dpkt.pcap.Reader(stream)
        except (ValueError, dpkt.dpkt.Error):  # tcpdump ended before its header: _read_messages has why
            return
        if reader.datalink() not in dpkt.pcap.dltoff:
            self._errors.append(f"link type {reader.datalink()} is not one the tap reads")
            return
        link = reader.dloff
        for stamp, packet in reader:
            # IPv4 and TCP header lengths by hand: dpkt's full decode of a packet costs 27 us
            # against 1 here, at thousands of frames a second beside the ring on two cores
            ip_header = (packet[link] & 0x0F) * 4
            tcp_header = (packet[link + ip_header + 12] >> 4) * 4
            frame = find_frame(packet[link + ip_header + tcp_header :], self.protocol)
            self.packets += 1
            if frame is not None:
                self._add(float(stamp) - self._offset, frame)

    def _read_messages(self, stream: IO[bytes]) -> None:
        for raw in stream:
            line = raw.decode(errors="replace")
            if "listening on" in line:  # ("tcpdump: listening on lo, ..." when writing pcap)
                self._listening.set()
            elif line.endswith("packets dropped by kernel\n"):
                self.dropped = int(line.split(" ", 1)[0])
            elif line.strip() and "packets captured" not in line and "received by filter" not in line:
                self._errors.append(line.strip())
