"""An outside tap on the wire: the kernel's arrival times of the token's frames at one TCP port
on loopback, captured by tcpdump (libpcap; the Debian package ``tcpdump``).

On direct links (``--topology links``) the token passes from node to node on TCP links that no
router and no subscriber sees; the one vantage point outside the ring is the wire. tcpdump is
the real component for it: a kernel packet filter keeps only the frames into one node's link
port, and each carries the kernel's own time stamp, so neither the tap's nor the ring's
scheduling moves the times it reports. Capturing needs CAP_NET_RAW (root here); without it, or
without tcpdump, :class:`WireTapError` says so.
"""

from __future__ import annotations

import shutil
import subprocess
import threading
import time

from tokenring.errors import TokenRingError
from tokenring.launcher import die_with_parent

#: a packet carrying a token frame is longer than the frame (514 bytes) alone; acks, keep-alives
#: and membership messages on the same link are far shorter
MIN_TOKEN_PACKET_BYTES = 514


class WireTapError(TokenRingError):
    """The capture could not start: no tcpdump, no right to capture, or it ended early."""


def tcpdump_path() -> str:
    """Where tcpdump is; raises :class:`WireTapError` if nowhere (a tool checks before it runs)."""
    # (Debian installs it in /usr/bin; some systems keep it in /usr/sbin, off a user's PATH)
    found = shutil.which("tcpdump") or shutil.which("tcpdump", path="/usr/sbin:/usr/bin")
    if found is None:
        raise WireTapError("the outside tap on direct links needs tcpdump (Debian package tcpdump)")
    return found


class WireTap:
    """Arrival times (s, the kernel's clock) of TCP packets of at least ``min_bytes`` into
    ``port`` on ``interface``: ``start()``, let the ring run, ``stop()``."""

    def __init__(self, port: int, *, interface: str = "lo", min_bytes: int = MIN_TOKEN_PACKET_BYTES):
        self.port = port
        self.interface = interface
        self.min_bytes = min_bytes
        self.arrivals: list[float] = []
        self._process: subprocess.Popen[str] | None = None
        self._listening = threading.Event()
        self._errors: list[str] = []
        self._threads: list[threading.Thread] = []

    def start(self, timeout_s: float = 10.0) -> None:
        """Start tcpdump and wait until it captures; raises :class:`WireTapError`."""
        command = [
            tcpdump_path(), "-i", self.interface, "-n", "-q", "-l", "--immediate-mode",
            "-tt", "--time-stamp-precision=nano",
            f"tcp dst port {self.port} and greater {self.min_bytes}",
        ]  # fmt: skip
        self._process = subprocess.Popen(
            command,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,  # a Ctrl-C reaches the tool, which ends the capture itself
            preexec_fn=die_with_parent,  # and a tool killed outright takes the capture with it
        )
        self._threads = [
            threading.Thread(target=self._read_arrivals, name="wiretap-out", daemon=True),
            threading.Thread(target=self._read_messages, name="wiretap-err", daemon=True),
        ]
        for thread in self._threads:
            thread.start()
        deadline = time.monotonic() + timeout_s
        while not self._listening.wait(0.05):
            if self._process.poll() is not None or time.monotonic() > deadline:
                self.stop()
                why = self._errors[-1] if self._errors else f"no capture within {timeout_s:.0f} s"
                raise WireTapError(f"tcpdump on {self.interface} port {self.port}: {why}")

    def stop(self) -> list[float]:
        """End the capture (tcpdump flushes what it holds); the arrival times, oldest first."""
        process = self._process
        if process is not None and process.poll() is None:
            process.terminate()
            try:
                process.wait(5.0)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        for thread in self._threads:
            thread.join(5.0)
        return self.arrivals

    def _read_arrivals(self) -> None:
        assert self._process is not None and self._process.stdout is not None
        for line in self._process.stdout:  # "1764431234.123456789 IP 127.0.0.1.40000 > ...: tcp 530"
            stamp = line.split(" ", 1)[0]
            seconds, _, fraction = stamp.partition(".")
            if seconds.isdigit() and fraction.isdigit():
                self.arrivals.append(int(seconds) + int(fraction) / 10 ** len(fraction))

    def _read_messages(self) -> None:
        assert self._process is not None and self._process.stderr is not None
        for line in self._process.stderr:
            if line.startswith("listening on"):
                self._listening.set()
            elif line.strip():
                self._errors.append(line.strip())
